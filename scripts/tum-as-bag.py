#!/usr/bin/env python3
"""The real Kinect sequence (TUM fr3 cabinet, ../shared/data/real/) as a
legged robot's ROS 2 bag, and an independent fit to compare groundcal's
answer with (issue 41: "its per-frame planes and the pattern map groundcal
reports, against your own independent fit").

    tum-as-bag.py OUT.mcap OUT-independent.json

Needs numpy, Pillow and the MCAP project's writer (mcap, mcap-ros2-support;
tests/mcap/requirements.txt).

The sequence has a hand-held camera and motion capture, no robot. It becomes
one thus:
- The body is fixed to the camera: body_from_optical is a chosen mount
  (MOUNT below, conventions.md's angles), so the body's pose in the room is
  the capture's camera pose times that mount's inverse.
- The floor of the room is one plane, fitted here from every frame's floor
  (each frame fitted on its own in inverse depth, then put in the room by
  the capture): that is the "independent fit".
- Each keyframe is a still pose with its feet planted: the six feet of a
  hexapod's stance on that floor, under the body (the ground frame under the
  body, turned with the body's heading: the ground does not see heading or
  place). Their positions in the body follow from the capture.
- The home stance: the same feet under a level body 0.6 m up.
- /tf_static holds a rough mount (MOUNT off by 3 degrees and 30 mm), as a
  robot's URDF would.

So the truth of the mount is MOUNT, up to the capture's own error against the
depth (the sequence's README: 0.9 degrees and 11.5 mm a frame on average),
which groundcal sees as feet and ground that disagree. The independent JSON
has, per keyframe, the floor measured in the frame and the floor the capture
predicts, both as groundcal's plane (a, b, c, d_m: the sensor frame's up
axis and height), and the fixed pattern per 8-px cell (raw units, 1 raw =
0.00307 1/m) averaged over the frames.
"""
import json
import math
import os
import sys

import numpy as np
from PIL import Image

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "mcap"))
from make_bag import (  # noqa: E402
    CAMERA_INFO,
    IMAGE,
    OPTICAL,
    START_NS,
    TF_MESSAGE,
    mount_rotation,
    quaternion,
    ros_point_m,
    stamp,
    transform,
)
from mcap.writer import CompressionType  # noqa: E402
from mcap_ros2.writer import Writer  # noqa: E402

D = os.path.realpath(os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "real", "tum-fr3-cabinet"))
FX, FY, CX, CY = 535.4, 539.2, 320.1, 247.6
W, H = 640, 480
RAW = 0.00307  # 1/m of inverse depth per raw unit (a Kinect's 1/b)
CELL = 8
# The chosen mount (alpha, beta, gamma deg; x, y, z mm): the camera 0.4 m up
# and 0.3 m forward of the body's centre, pitched 53 degrees down, the middle
# of the sequence's 43-63.
MOUNT = (0.0, -53.0, 0.0, 300.0, 400.0, 0.0)
ROUGH = (3.0, -50.0, 0.0, 330.0, 370.0, 0.0)
SENSOR_FROM_OPTICAL = np.array([[0, 0, 1, 0], [0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]], float)
ROS_FROM_GROUNDCAL = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)
# A hexapod's stance in the ground frame (mm; x forward, z right).
STANCE = [(693, 400), (0, 800), (-693, 400), (-693, -400), (0, -800), (693, -400)]


def rot_q(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def pose_matrix(alpha, beta, gamma, x, y, z):
    m = np.eye(4)
    m[:3, :3] = np.array(mount_rotation(alpha, beta, gamma))
    m[:3, 3] = (x / 1e3, y / 1e3, z / 1e3)
    return m


def fit_floor(depth_m, world_from_optical):
    """The floor of one frame in inverse depth, 1/z = c0 u + c1 v + c2, from
    the readings the capture puts near the floor; residuals in raw units."""
    vv, uu = np.mgrid[0:H, 0:W]
    valid = depth_m > 0
    rays = np.stack([(uu - CX) / FX * depth_m, (vv - CY) / FY * depth_m, depth_m], -1)
    world = rays @ world_from_optical[:3, :3].T + world_from_optical[:3, 3]
    heights = world[..., 2][valid]
    hist, edges = np.histogram(heights, bins=np.arange(-0.5, 0.5, 0.01))
    floor_z = edges[np.argmax(hist)] + 0.005
    near = valid & (np.abs(world[..., 2] - floor_z) < 0.08)
    w = np.where(valid, 1 / np.maximum(depth_m, 1e-9), 0)
    keep = near
    for _ in range(5):
        a = np.stack([uu[keep], vv[keep], np.ones(keep.sum())], 1)
        c, *_ = np.linalg.lstsq(a, w[keep], rcond=None)
        residual = (w - (c[0] * uu + c[1] * vv + c[2])) / RAW
        keep = near & (np.abs(residual) < 3)
    return c, np.where(keep, residual, np.nan)


def plane_of(c):
    """The inverse-depth plane as (up, height) in the optical frame: a point
    P is up·P + height above the floor."""
    n = np.array([c[0] * FX, c[1] * FY, c[0] * CX + c[1] * CY + c[2]])
    return -n / np.linalg.norm(n), 1 / np.linalg.norm(n)


def groundcal_plane(up_optical, height):
    up = SENSOR_FROM_OPTICAL[:3, :3] @ up_optical
    return {"a": up[0], "b": up[1], "c": up[2], "d_m": height}


def main():
    out_bag, out_json = sys.argv[1:3]
    lines = [l.split() for l in open(os.path.join(D, "truth_cam_poses.txt")) if l.strip()]
    world_from_optical = []
    for l in lines:
        m = np.eye(4)
        m[:3, :3] = rot_q([float(v) for v in l[4:8]])
        m[:3, 3] = [float(v) for v in l[1:4]]
        world_from_optical.append(m)
    depths = [
        np.array(Image.open(os.path.join(D, "depth_imgs", f"{i:04d}_depth_raw.png"))).astype(float) / 5000
        for i in range(len(lines))
    ]

    # Every frame's floor on its own, and the room's floor from them all.
    fits = [fit_floor(z, m) for z, m in zip(depths, world_from_optical)]
    normals, offsets = [], []
    for (c, _), m in zip(fits, world_from_optical):
        up, height = plane_of(c)
        up_w = m[:3, :3] @ up
        normals.append(up_w)
        offsets.append(height - up_w @ m[:3, 3])  # up_w · X + offset = 0 on the floor
    floor_up = np.mean(normals, 0)
    floor_up /= np.linalg.norm(floor_up)
    floor_offset = float(np.mean([o for o in offsets]))

    body_from_optical = pose_matrix(*MOUNT) @ SENSOR_FROM_OPTICAL
    poses_feet, measured, predicted = [], [], []
    for (c, _), m in zip(fits, world_from_optical):
        world_from_body = m @ np.linalg.inv(body_from_optical)
        origin = world_from_body[:3, 3]
        # The ground frame under the body: x the body's heading on the floor,
        # y up, z right.
        foot_of_origin = origin - (floor_up @ origin + floor_offset) * floor_up
        forward = world_from_body[:3, 0] - (world_from_body[:3, 0] @ floor_up) * floor_up
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, floor_up)
        body_from_world = np.linalg.inv(world_from_body)
        feet = []
        for x, z in STANCE:
            p = foot_of_origin + forward * x / 1e3 + right * z / 1e3
            feet.append(list(body_from_world[:3, :3] @ p * 1e3 + body_from_world[:3, 3] * 1e3))
        poses_feet.append(feet)
        up, height = plane_of(c)
        measured.append(groundcal_plane(up, height))
        up_opt = m[:3, :3].T @ floor_up
        predicted.append(groundcal_plane(up_opt, float(floor_up @ m[:3, 3] + floor_offset)))

    # The fixed pattern per 8-px cell over the frames (raw units).
    residuals = np.stack([r for _, r in fits])
    cells = residuals.reshape(len(fits), H // CELL, CELL, W // CELL, CELL)
    with np.errstate(invalid="ignore"):
        sums = np.nansum(cells, axis=(0, 2, 4))
        counts = np.sum(~np.isnan(cells), axis=(0, 2, 4))
        pattern = np.where(counts >= 64, sums / np.maximum(counts, 1), np.nan)
    json.dump(
        {
            "mount": dict(zip(["alpha_deg", "beta_deg", "gamma_deg", "px_mm", "py_mm", "pz_mm"], MOUNT)),
            "floor_up_world": list(floor_up),
            "floor_offset_m": floor_offset,
            "measured": measured,
            "predicted_by_capture": predicted,
            "pattern_cell_px": CELL,
            "pattern_raw": [None if math.isnan(v) else float(v) for v in pattern.ravel()],
            "pattern_columns": W // CELL,
        },
        open(out_json, "w"),
    )

    # The bag: hips on /tf_static, feet on /tf at 20 Hz, one image a pose.
    home = [[x, -600.0, z] for x, z in STANCE]
    hips = [ros_point_m((0.5 * x, 0.0, 0.5 * z)) for x, _, z in home]
    rough = ROS_FROM_GROUNDCAL @ pose_matrix(*ROUGH) @ SENSOR_FROM_OPTICAL
    with open(out_bag, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        image_schema = writer.register_msgdef("sensor_msgs/msg/Image", IMAGE)
        info_schema = writer.register_msgdef("sensor_msgs/msg/CameraInfo", CAMERA_INFO)
        tf_schema = writer.register_msgdef("tf2_msgs/msg/TFMessage", TF_MESSAGE)
        static = [transform(START_NS, "base_link", f"hip_{k + 1}", hip) for k, hip in enumerate(hips)]
        static.append(transform(START_NS, "base_link", OPTICAL, tuple(rough[:3, 3]), quaternion(rough[:3, :3].tolist())))
        writer.write_message("/tf_static", tf_schema, {"transforms": static}, START_NS, START_NS)

        def write_feet(ns, feet_mm):
            transforms = [
                transform(ns, f"hip_{k + 1}", f"foot_{k + 1}", tuple(a - b for a, b in zip(ros_point_m(foot), hip)))
                for k, (foot, hip) in enumerate(zip(feet_mm, hips))
            ]
            writer.write_message("/tf", tf_schema, {"transforms": transforms}, ns, ns)

        def write_image(ns, depth_m):
            header = {"stamp": stamp(ns), "frame_id": OPTICAL}
            data = np.where(depth_m > 0, depth_m, np.nan).astype("<f4").tobytes()
            image = {"header": header, "height": H, "width": W, "encoding": "32FC1",
                     "is_bigendian": 0, "step": W * 4, "data": data}
            info = {"header": header, "height": H, "width": W, "distortion_model": "plumb_bob",
                    "d": [0.0] * 5, "k": [FX, 0.0, CX, 0.0, FY, CY, 0.0, 0.0, 1.0],
                    "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                    "p": [FX, 0.0, CX, 0.0, 0.0, FY, CY, 0.0, 0.0, 0.0, 1.0, 0.0],
                    "binning_x": 0, "binning_y": 0,
                    "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}}
            writer.write_message("/camera/depth/image_raw", image_schema, image, ns, ns)
            writer.write_message("/camera/depth/camera_info", info_schema, info, ns, ns)

        now, step = START_NS, 50_000_000
        for _ in range(21):
            write_feet(now, home)
            now += step
        before = home
        for feet, depth in zip(poses_feet, depths):
            for k in range(1, 21):
                s = k / 20
                write_feet(now, [[p + s * (q - p) for p, q in zip(a, b)] for a, b in zip(before, feet)])
                now += step
            for k in range(13):
                write_feet(now, feet)
                if k == 8:
                    write_image(now + 1, depth)
                now += step
            before = feet
        writer.finish()
    print(json.dumps({"poses": len(poses_feet), "floor_up_world": list(np.round(floor_up, 5))}))


if __name__ == "__main__":
    main()
