#!/usr/bin/env python3
"""A simulated quadruped's calibration session, written as a ROS 2 bag by
`rosbags`' own Writer (neither groundcal's writer nor the MCAP project's that
make_bag.py uses), with its own renderer of the depth camera:

    make_quadruped_bag.py SCHEDULE.toml OUT_DIR [--seed N] [--slip FOOT@POSE]
        [--pattern-scale K] [--info-baseline] [--tof] [--tiny]

- The robot: four feet planted in a 500 x 300 mm rectangle, each reached
  from a hip through a knee (thigh and shank 220 mm, solved in the plane of
  the leg and the body's forward axis): base_link -> {lf,rf,lh,rh}_hip on
  /tf_static, hip -> knee -> foot on /tf at 20 Hz.
- The body: the schedule's poses (ground_from_robot, groundcal's convention,
  `plan --design` within a quadruped's limits), each reached in 1 s and held
  for 0.6 s, the home stance first.
- The camera: an 848 x 480 active-stereo depth camera (fx = fy = 425 px,
  baseline 50 mm: 21.25 px*m of disparity), 16UC1 millimetres, two frames at
  each still pose. Its errors are in its own disparity, after the Kinect as it
  really is (issue 41) scaled to pixels: white noise of 0.05 px and a field
  smoothed over about 8 px of 0.03 px, both drawn every frame; a fixed pattern
  of the device (smooth waves and a bowl, 0.051 px RMS, 9.5 mm RMS at 2 m);
  the disparity rounded to 1/32 px and the depth to the millimetre; nothing
  nearer than 0.3 m or farther than 4 m.
- /tf_static also holds a rough mount (3 degrees and 30 mm off the truth), as
  the robot's own URDF would.
- --tof: a time-of-flight camera instead, which measures the distance: its
  noise in depth, 3 mm + 0.2 % of the distance, drawn every frame, no
  disparity and no pattern (groundcal must refuse it, not calibrate it as a
  disparity camera).
- --tiny: a 32 x 18 camera and the schedule's first three poses, a bag of a
  few kilobytes (the fuzzer's seed, fuzz/corpus/bag_session).
- --pattern-scale 2.5: the fixed pattern 2.5 times as large (0.13 px RMS,
  0.40 px at its largest cell: 75 mm at 2 m, past the 45 mm a Kinect's
  pattern is checked for, within the 0.48 px that is on the Kinect).
- --info-baseline: the CameraInfo's projection matrix carries the baseline
  (P[3] = -fx * baseline, as a stereo pair's second camera's does); without
  it P[3] is 0, as a RealSense's depth CameraInfo has it.
- --slip 2@20: foot 2 slips on its way to pose 20 (15 mm forward and 10 mm
  into the ground) and stays there.

Writes OUT_DIR (a rosbag2 directory: metadata.yaml and one .mcap file) and
prints the truth as JSON: the mount (groundcal's convention), the bag's file.
"""
import argparse
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

W, H = 848, 480
FX = FY = 425.0
CX, CY = 423.5, 239.5
BASELINE_M = 0.05
FB = FX * BASELINE_M
# The truth: alpha, beta, gamma (deg); px, py, pz (mm), groundcal's convention
# (conventions.md: body X forward, Y up, Z right; R = Ry(a) Rz(b) Rx(g)).
MOUNT = (1.2, -35.0, 0.8, 280.0, 60.0, 12.0)
ROUGH = (4.2, -32.0, 0.8, 310.0, 30.0, 12.0)
# The feet in the ground frame (mm; x forward, z right), foot 1 first.
FEET_NAMES = ["lf", "rf", "lh", "rh"]
FEET_G = [(250.0, -150.0), (250.0, 150.0), (-250.0, -150.0), (-250.0, 150.0)]
HIPS_R = [(200.0, 0.0, -100.0), (200.0, 0.0, 100.0), (-200.0, 0.0, -100.0), (-200.0, 0.0, 100.0)]
THIGH_M = SHANK_M = 0.22
SENSOR_FROM_OPTICAL = np.array([[0, 0, 1], [0, -1, 0], [1, 0, 0]], float)
ROS_FROM_GROUNDCAL = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)
OPTICAL = "camera_depth_optical_frame"
START_NS = 1_700_000_000 * 10**9


def rotation(alpha, beta, gamma):
    a, b, g = (math.radians(v) for v in (alpha, beta, gamma))
    ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    rz = np.array([[math.cos(b), -math.sin(b), 0], [math.sin(b), math.cos(b), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, math.cos(g), -math.sin(g)], [0, math.sin(g), math.cos(g)]])
    return ry @ rz @ rx


def pose(values):
    """(R, t in metres) of alpha, beta, gamma deg and x, y, z mm."""
    return rotation(*values[:3]), np.array(values[3:]) / 1e3


def quaternion(r):
    w = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return x, y, z, w


def read_schedule(path):
    """The home pose and the poses of a groundcal schedule (its inline tables)."""
    keys = ["alpha_deg", "beta_deg", "gamma_deg", "px_mm", "py_mm", "pz_mm"]

    def values(line):
        found = dict(re.findall(r"(\w+)\s*=\s*(-?[\d.]+)", line))
        return tuple(float(found.get(k, 0.0)) for k in keys)

    home, poses = None, []
    for line in Path(path).read_text().splitlines():
        line = line.split("#")[0]
        if line.strip().startswith("home"):
            home = values(line)
        elif "alpha_deg" in line:
            poses.append(values(line))
    return home, poses


def box_blur(field, size):
    """A box mean of `size` pixels along both axes (edges clamped)."""
    for axis in (0, 1):
        pad = [(0, 0), (0, 0)]
        pad[axis] = (size // 2 + 1, size // 2)
        padded = np.pad(field, pad, mode="edge")
        c = np.cumsum(padded, axis=axis)
        if axis == 0:
            field = (c[size:] - c[:-size]) / size
        else:
            field = (c[:, size:] - c[:, :-size]) / size
    return field


def device_pattern():
    """The camera's fixed pattern in disparity pixels."""
    v, u = np.mgrid[0:H, 0:W].astype(float)
    waves = 0.07 * np.sin(2 * np.pi * u / 310.0 + 0.4) * np.cos(2 * np.pi * v / 260.0)
    r2 = ((u - CX) / W) ** 2 + ((v - CY) / H) ** 2
    bowl = 0.35 * (r2 - r2.mean())
    return waves + bowl


def render(ground_from_optical, pattern, rng, tof=False):
    """One 16UC1 frame of the ground plane y = 0 (millimetres, 0: none)."""
    r, t = ground_from_optical
    v, u = np.mgrid[0:H, 0:W].astype(float)
    rays = np.stack([(u - CX) / FX, (v - CY) / FY, np.ones_like(u)], -1)
    up = rays @ r[1]  # each ray's rise per metre of depth
    with np.errstate(divide="ignore", invalid="ignore"):
        z = -t[1] / up
    valid = (z > 0.3) & (z < 4.0) & np.isfinite(z)
    if tof:
        noisy = z + (0.003 + 0.002 * z) * rng.standard_normal((H, W))
        depth = np.where(valid & (noisy > 0.3) & (noisy < 4.0), noisy, 0.0)
        return np.round(depth * 1e3).astype("<u2")
    disparity = np.where(valid, FB / np.where(valid, z, 1.0), 0.0)
    smooth = box_blur(box_blur(rng.standard_normal((H, W)), 5), 5)
    smooth *= 0.03 / smooth.std()
    noisy = disparity + pattern + smooth + 0.05 * rng.standard_normal((H, W))
    noisy = np.round(noisy * 32) / 32
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(valid & (noisy > 0), FB / noisy, 0.0)
    depth = np.where((depth > 0.3) & (depth < 4.0), depth, 0.0)
    return np.round(depth * 1e3).astype("<u2")


def knee(hip, foot):
    """The knee of a two-link leg from hip to foot, in the plane of the leg
    and the body's forward axis, bent forward."""
    leg = foot - hip
    reach = np.linalg.norm(leg)
    along = (THIGH_M**2 - SHANK_M**2 + reach**2) / (2 * reach)
    side = math.sqrt(max(THIGH_M**2 - along**2, 0.0))
    unit = leg / reach
    forward = np.array([1.0, 0.0, 0.0]) - unit[0] * unit
    forward /= np.linalg.norm(forward)
    return hip + along * unit + side * forward


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("schedule")
    parser.add_argument("out")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--tiny", action="store_true", help="a 32 x 18 camera, three poses")
    parser.add_argument("--tof", action="store_true", help="a time-of-flight camera")
    parser.add_argument("--slip", help="FOOT@POSE: that foot slips 18 mm on the way to that pose")
    parser.add_argument("--pattern-scale", type=float, default=1.0, help="the fixed pattern times this")
    parser.add_argument("--info-baseline", action="store_true", help="P[3] = -fx * baseline")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    home, poses = read_schedule(args.schedule)
    if args.tiny:
        global W, H, FX, FY, CX, CY, FB
        W, H = 32, 18
        FX = FY = 425.0 * 32 / 848
        CX, CY = (W - 1) / 2, (H - 1) / 2
        FB = FX * BASELINE_M
        poses = poses[:3]
    slip = tuple(int(x) for x in args.slip.split("@")) if args.slip else None
    mount_r, mount_t = pose(MOUNT)
    robot_from_optical = (mount_r @ SENSOR_FROM_OPTICAL, mount_t)
    pattern = args.pattern_scale * device_pattern()
    feet_g = [np.array([x / 1e3, 0.0, z / 1e3]) for x, z in FEET_G]
    hips_base = [ROS_FROM_GROUNDCAL @ (np.array(h) / 1e3) for h in HIPS_R]

    store = get_typestore(Stores.ROS2_HUMBLE)
    msg = store.types
    Time = msg["builtin_interfaces/msg/Time"]
    Header = msg["std_msgs/msg/Header"]
    Image = msg["sensor_msgs/msg/Image"]
    CameraInfo = msg["sensor_msgs/msg/CameraInfo"]
    Roi = msg["sensor_msgs/msg/RegionOfInterest"]
    TFMessage = msg["tf2_msgs/msg/TFMessage"]
    Stamped = msg["geometry_msgs/msg/TransformStamped"]
    Transform = msg["geometry_msgs/msg/Transform"]
    Vector3 = msg["geometry_msgs/msg/Vector3"]
    Quaternion = msg["geometry_msgs/msg/Quaternion"]

    def header(ns, frame):
        return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)

    def stamped(ns, parent, child, translation, rot=(0.0, 0.0, 0.0, 1.0)):
        return Stamped(
            header=header(ns, parent),
            child_frame_id=child,
            transform=Transform(
                translation=Vector3(x=float(translation[0]), y=float(translation[1]), z=float(translation[2])),
                rotation=Quaternion(x=rot[0], y=rot[1], z=rot[2], w=rot[3]),
            ),
        )

    out = Path(args.out)
    counts = {"images": 0, "tf": 0, "poses": len(poses)}
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        tf = writer.add_connection("/tf", TFMessage.__msgtype__, typestore=store)
        tf_static = writer.add_connection("/tf_static", TFMessage.__msgtype__, typestore=store)
        image_topic = writer.add_connection("/camera/depth/image_rect_raw", Image.__msgtype__, typestore=store)
        info_topic = writer.add_connection("/camera/depth/camera_info", CameraInfo.__msgtype__, typestore=store)

        def write(connection, ns, message):
            writer.write(connection, ns, store.serialize_cdr(message, message.__msgtype__))

        rough_r, rough_t = pose(ROUGH)
        static = [stamped(START_NS, "base_link", f"{name}_hip", hip) for name, hip in zip(FEET_NAMES, hips_base)]
        base_from_optical = ROS_FROM_GROUNDCAL @ rough_r @ SENSOR_FROM_OPTICAL
        static.append(
            stamped(START_NS, "base_link", OPTICAL, ROS_FROM_GROUNDCAL @ rough_t, quaternion(base_from_optical))
        )
        write(tf_static, START_NS, TFMessage(transforms=static))

        def write_feet(ns, body):
            r, t = body
            transforms = []
            for name, foot, hip in zip(FEET_NAMES, feet_g, hips_base):
                foot_base = ROS_FROM_GROUNDCAL @ (r.T @ (foot - t))
                k = knee(hip, foot_base)
                transforms.append(stamped(ns, f"{name}_hip", f"{name}_knee", k - hip))
                transforms.append(stamped(ns, f"{name}_knee", f"{name}_foot", foot_base - k))
            write(tf, ns, TFMessage(transforms=transforms))
            counts["tf"] += 1

        def write_frame(ns, body):
            r, t = body
            ground_from_optical = (r @ robot_from_optical[0], r @ robot_from_optical[1] + t)
            depth = render(ground_from_optical, pattern, rng, tof=args.tof)
            write(
                image_topic,
                ns,
                Image(
                    header=header(ns, OPTICAL),
                    height=H,
                    width=W,
                    encoding="16UC1",
                    is_bigendian=0,
                    step=W * 2,
                    data=np.frombuffer(depth.tobytes(), dtype=np.uint8),
                ),
            )
            write(
                info_topic,
                ns,
                CameraInfo(
                    header=header(ns, OPTICAL),
                    height=H,
                    width=W,
                    distortion_model="plumb_bob",
                    d=np.zeros(5),
                    k=np.array([FX, 0, CX, 0, FY, CY, 0, 0, 1], float),
                    r=np.eye(3).flatten(),
                    p=np.array([FX, 0, CX, -FB if args.info_baseline else 0, 0, FY, CY, 0, 0, 0, 1, 0], float),
                    binning_x=0,
                    binning_y=0,
                    roi=Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
                ),
            )
            counts["images"] += 1

        ns = START_NS
        step = 50_000_000  # 20 Hz
        values = home
        for _ in range(21):  # the home stance, 1 s, no image
            write_feet(ns, pose(values))
            ns += step
        for k, target in enumerate(poses, start=1):
            a, b = np.array(values), np.array(target)
            for i in range(1, 21):  # 1 s of motion
                if slip and slip[1] == k and i == 10:
                    feet_g[slip[0] - 1] = feet_g[slip[0] - 1] + np.array([0.015, -0.010, 0.0])
                write_feet(ns, pose(a + (b - a) * i / 20))
                ns += step
            values = target
            current = pose(target)
            for i in range(13):  # 0.6 s still, a frame at 0.35 s and 0.5 s
                write_feet(ns, current)
                if i in (7, 10):
                    write_frame(ns + 1_000_000, current)
                ns += step
    files = sorted(out.glob("*.mcap"))
    json.dump(
        {
            "bag": str(files[0]),
            "mount": dict(zip(["alpha_deg", "beta_deg", "gamma_deg", "px_mm", "py_mm", "pz_mm"], MOUNT)),
            "foot_frames": [f"{name}_foot" for name in FEET_NAMES],
            "counts": counts,
            "pattern_rms_px": float(pattern.std()),
        },
        sys.stdout,
    )
    print()


if __name__ == "__main__":
    main()
