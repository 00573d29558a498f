#!/usr/bin/env python3
"""Writes a ROS 2 bag (MCAP) as another robot's stack would record it, from a
groundcal recording, with the MCAP project's own ROS 2 writer
(`mcap-ros2-support`), not groundcal's code:

    make_bag.py RECORDING_DIR OUT.mcap [--encoding 16UC1|32FC1]
                [--compression zstd|lz4|none] [--poison fx-inf|camera-nan]

The bag has what a hexapod's drivers publish, at their own rates:
- /camera/depth/image_raw (sensor_msgs/msg/Image): 16UC1 millimetres or 32FC1
  metres, computed here from the raw frames with the depth model of
  conventions.md; at each pose its recorded frames, and while the body moves
  a stale frame of the pose before at 5 Hz (no recording has frames in
  motion: a reader must leave them out);
- /camera/depth/camera_info (sensor_msgs/msg/CameraInfo) with every image;
- /tf at 20 Hz: base_link -> hip_k -> foot_k, the hips static on
  /tf_static, the feet moving between poses (linearly) and still at them;
- /tf_static: base_link -> hip_k, and base_link -> camera_depth_optical_frame
  at the recording's nominal mount (the robot's own rough guess).

Frames follow REP 103 (conventions.md's axes turned). The home stance comes
first, 1 s with no image; each pose is 1 s of motion, then 0.6 s still.
With --poison, one number a reader must refuse: fx = inf in every
CameraInfo, or NaN in the camera's static transform.

Prints one JSON object (counts) on stdout.
"""
import argparse
import json
import math
import struct
import sys
from pathlib import Path

from mcap.writer import CompressionType
from mcap_ros2.writer import Writer

from check_session import (
    ROS_FROM_GROUNDCAL,
    SENSOR_FROM_OPTICAL,
    depth_mm_table,
    matmul,
    read_raw,
)

SEPARATOR = "=" * 80
TIME = "int32 sec\nuint32 nanosec\n"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
ROI = "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
QUATERNION = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
TRANSFORM = "Vector3 translation\nQuaternion rotation\n"
TRANSFORM_STAMPED = "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"


def msgdef(fields, *uses):
    text = fields
    for name, body in uses:
        text += f"{SEPARATOR}\nMSG: {name}\n{body}"
    return text


IMAGE = msgdef(
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
    "uint8 is_bigendian\nuint32 step\nuint8[] data\n",
    ("std_msgs/Header", HEADER),
    ("builtin_interfaces/Time", TIME),
)
CAMERA_INFO = msgdef(
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
    "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
    "uint32 binning_y\nRegionOfInterest roi\n",
    ("std_msgs/Header", HEADER),
    ("builtin_interfaces/Time", TIME),
    ("sensor_msgs/RegionOfInterest", ROI),
)
TF_MESSAGE = msgdef(
    "geometry_msgs/TransformStamped[] transforms\n",
    ("geometry_msgs/TransformStamped", TRANSFORM_STAMPED),
    ("std_msgs/Header", HEADER),
    ("builtin_interfaces/Time", TIME),
    ("geometry_msgs/Transform", TRANSFORM),
    ("geometry_msgs/Vector3", VECTOR3),
    ("geometry_msgs/Quaternion", QUATERNION),
)

OPTICAL = "camera_depth_optical_frame"
START_NS = 1_700_000_000 * 10**9


def stamp(ns):
    return {"sec": ns // 10**9, "nanosec": ns % 10**9}


def quaternion(r):
    """x, y, z, w of a rotation matrix (Shepperd's method)."""
    trace = r[0][0] + r[1][1] + r[2][2]
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2
        return ((r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s, 0.25 * s)
    if r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        return (0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s, (r[2][1] - r[1][2]) / s)
    if r[1][1] > r[2][2]:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        return ((r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s, (r[0][2] - r[2][0]) / s)
    s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
    return ((r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s, (r[1][0] - r[0][1]) / s)


def transform(ns, parent, child, translation, rotation=(0.0, 0.0, 0.0, 1.0)):
    return {
        "header": {"stamp": stamp(ns), "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": dict(zip("xyz", translation)),
            "rotation": dict(zip("xyzw", rotation)),
        },
    }


def ros_point_m(foot_mm):
    """A point of groundcal's body frame (mm) in base_link (m)."""
    x, y, z = foot_mm
    return (x / 1e3, -z / 1e3, y / 1e3)


def mount_rotation(alpha_deg, beta_deg, gamma_deg):
    """conventions.md: R = Ry(α) · Rz(β) · Rx(γ)."""
    a, b, g = (math.radians(v) for v in (alpha_deg, beta_deg, gamma_deg))
    ry = [[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]]
    rz = [[math.cos(b), -math.sin(b), 0], [math.sin(b), math.cos(b), 0], [0, 0, 1]]
    rx = [[1, 0, 0], [0, math.cos(g), -math.sin(g)], [0, math.sin(g), math.cos(g)]]
    return matmul(matmul(ry, rz), rx)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("recording")
    parser.add_argument("out")
    parser.add_argument("--encoding", choices=["16UC1", "32FC1"], default="16UC1")
    parser.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    parser.add_argument("--poison", choices=["fx-inf", "camera-nan"])
    args = parser.parse_args()
    recording = Path(args.recording)
    session = json.loads((recording / "session.json").read_text())
    poses = [json.loads(line) for line in (recording / "poses.jsonl").read_text().splitlines() if line.strip()]
    intrinsics = session["kinect"]["intrinsics"]
    width, height = intrinsics["width"], intrinsics["height"]
    model = session["kinect"].get("depth_model", {"kind": "zero-plane"})
    millimetres = depth_mm_table(model)

    # Per raw value: millimetres (16UC1), or metres (32FC1; for the
    # inverse-linear model the exact depth, not rounded to the millimetre).
    if args.encoding == "16UC1":
        table, code = millimetres, "H"
    elif model.get("kind") == "inverse-linear":
        a, b = model["a"], model["b"]
        table = [1.0 / (a + b * v) if v < 2047 and a + b * v > 0 else math.nan for v in range(2048)]
        code = "f"
    else:
        table = [mm / 1e3 if mm else math.nan for mm in millimetres]
        code = "f"

    def depth_bytes(raw):
        return struct.pack(f"<{len(raw)}{code}", *[table[min(v, 2047)] for v in raw])

    compression = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[
        args.compression
    ]
    counts = {"images": 0, "stale_images": 0, "tf": 0}
    with open(args.out, "wb") as out:
        writer = Writer(out, compression=compression)
        image_schema = writer.register_msgdef("sensor_msgs/msg/Image", IMAGE)
        info_schema = writer.register_msgdef("sensor_msgs/msg/CameraInfo", CAMERA_INFO)
        tf_schema = writer.register_msgdef("tf2_msgs/msg/TFMessage", TF_MESSAGE)

        # The hips: fixed points of the body, each foot's parent.
        home_feet = session["home"]["feet_body_mm"]
        hips = [ros_point_m((0.5 * x, 0.0, 0.5 * z)) for x, _, z in home_feet]
        static = [transform(START_NS, "base_link", f"hip_{k + 1}", hip) for k, hip in enumerate(hips)]
        nominal = session.get("nominal_mount")
        if nominal:
            robot_from_sensor = [
                row + [p / 1e3]
                for row, p in zip(
                    mount_rotation(nominal["alpha_deg"], nominal["beta_deg"], nominal["gamma_deg"]),
                    (nominal["px_mm"], nominal["py_mm"], nominal["pz_mm"]),
                )
            ] + [[0, 0, 0, 1]]
            m = matmul(matmul(ROS_FROM_GROUNDCAL, robot_from_sensor), SENSOR_FROM_OPTICAL)
            x = math.nan if args.poison == "camera-nan" else m[0][3]
            static.append(
                transform(START_NS, "base_link", OPTICAL, (x, m[1][3], m[2][3]), quaternion(m))
            )
        writer.write_message("/tf_static", tf_schema, {"transforms": static}, START_NS, START_NS)

        def write_feet(ns, feet_mm):
            transforms = []
            for k, (foot, hip) in enumerate(zip(feet_mm, hips)):
                p = ros_point_m(foot)
                transforms.append(
                    transform(ns, f"hip_{k + 1}", f"foot_{k + 1}", tuple(a - b for a, b in zip(p, hip)))
                )
            writer.write_message("/tf", tf_schema, {"transforms": transforms}, ns, ns)
            counts["tf"] += 1

        def write_image(ns, data):
            header = {"stamp": stamp(ns), "frame_id": OPTICAL}
            bytes_per_pixel = 2 if args.encoding == "16UC1" else 4
            image = {
                "header": header,
                "height": height,
                "width": width,
                "encoding": args.encoding,
                "is_bigendian": 0,
                "step": width * bytes_per_pixel,
                "data": data,
            }
            fx, fy, cx, cy = intrinsics["fx"], intrinsics["fy"], intrinsics["cx"], intrinsics["cy"]
            if args.poison == "fx-inf":
                fx = math.inf
            info = {
                "header": header,
                "height": height,
                "width": width,
                "distortion_model": "plumb_bob",
                "d": [0.0] * 5,
                "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
                "binning_x": 0,
                "binning_y": 0,
                "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
            }
            writer.write_message("/camera/depth/image_raw", image_schema, image, ns, ns)
            writer.write_message("/camera/depth/camera_info", info_schema, info, ns, ns)

        now = START_NS
        tf_step, stale_step = 50_000_000, 200_000_000
        for _ in range(21):  # the home stance, 1 s
            write_feet(now, home_feet)
            now += tf_step
        before, stale = home_feet, None
        for pose in poses:
            feet = pose["feet_body_mm"]
            # 1 s of motion: the feet move in the body; a stale image at 5 Hz.
            for step in range(1, 21):
                s = step / 20
                write_feet(now, [[p + s * (q - p) for p, q in zip(a, b)] for a, b in zip(before, feet)])
                # Captured while moving (never at the step that arrives).
                if stale is not None and step < 20 and (step * tf_step) % stale_step == 2 * tf_step:
                    write_image(now + 1, stale)
                    counts["stale_images"] += 1
                now += tf_step
            # 0.6 s still; the pose's frames from 0.3 s on, 33 ms apart.
            frames = {
                now + 300_000_000 + k * 33_000_000: name for k, name in enumerate(pose["depth_frames"])
            }
            for _ in range(13):
                write_feet(now, feet)
                for ns in sorted(f for f in frames if now <= f < now + tf_step):
                    raw = read_raw(recording / "kinect" / frames[ns], width, height)
                    stale = depth_bytes(raw)
                    write_image(ns, stale)
                    counts["images"] += 1
                now += tf_step
            before = feet
        writer.finish()
    print(json.dumps(counts))


if __name__ == "__main__":
    sys.exit(main())
