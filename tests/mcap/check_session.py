#!/usr/bin/env python3
"""Reads a groundcal session's MCAP file with the MCAP project's own Python
packages (`mcap`, `mcap-ros2-support`), not groundcal's code, and checks it
against the recording it came from and the result groundcal printed.

    check_session.py FILE.mcap RECORDING_DIR RESULT.json

Prints one JSON object (topics and counts, what was compared) and exits 0,
or names the first thing that is wrong and exits 1. The depth model and the
frames are read here from recording.md and conventions.md, independently.
"""
import json
import math
import struct
import sys
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

OPTICAL = "camera_depth_optical_frame"


def fail(message):
    print(f"check_session: {message}", file=sys.stderr)
    sys.exit(1)


def check(condition, message):
    if not condition:
        fail(message)


def depth_mm_table(model):
    """Millimetres per raw value (conventions.md), 0 for no reading."""
    kind = model.get("kind", "zero-plane")
    table = []
    for raw in range(2048):
        z_mm = None
        if raw < 2047:
            if kind == "zero-plane":
                r = model.get("reference_distance_mm", 120.0)
                p = model.get("reference_pixel_size_mm", 0.1052)
                e = model.get("emitter_distance_cm", 7.5)
                c = model.get("const_shift", 200.0)
                s = ((raw - 4 * c) / 4 - 0.375) * p
                if e - s != 0:
                    z_mm = 10 * (s * r / (e - s) + r)
            else:
                denominator = model["a"] + model["b"] * raw
                if denominator != 0:
                    z_mm = 1000.0 / denominator
        if z_mm is None or not math.isfinite(z_mm) or not (0.5 <= z_mm < 65535.5):
            table.append(0)
        else:
            table.append(int(math.floor(z_mm + 0.5)))
    return table


def frame_time_ns(name):
    """The capture time in a fakenect name, `d-<seconds>-<timestamp>.pgm`."""
    return round(float(name.split("-")[1]) * 1e9)


def read_raw(path, width, height):
    data = path.read_bytes()
    header = f"P5 {width} {height} 65535\n".encode()
    check(data.startswith(header), f"{path}: not a fakenect depth frame")
    return struct.unpack(f"<{width * height}H", data[len(header):])


def quaternion_matrix(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(len(b))) for j in range(len(b[0]))] for i in range(len(a))]


def transpose(a):
    return [list(row) for row in zip(*a)]


def homogeneous(transform):
    r = quaternion_matrix(transform.rotation)
    t = transform.translation
    return [r[0] + [t.x], r[1] + [t.y], r[2] + [t.z], [0, 0, 0, 1]]


# conventions.md: groundcal's frames (X forward, Y up, Z right) against
# REP 103's (x forward, y left, z up), and the sensor against the optical.
ROS_FROM_GROUNDCAL = [[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]]
SENSOR_FROM_OPTICAL = [[0, 0, 1, 0], [0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]]


def main():
    mcap_path, recording_dir, result_path = sys.argv[1:4]
    recording = Path(recording_dir)
    result = json.loads(Path(result_path).read_text())
    session = json.loads((recording / "session.json").read_text())
    poses = [json.loads(line) for line in (recording / "poses.jsonl").read_text().splitlines() if line.strip()]
    kinect = session.get("kinect", {})
    intrinsics = kinect.get("intrinsics", {"fx": 570.34, "fy": 570.34, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480})
    width, height = intrinsics["width"], intrinsics["height"]
    millimetres = depth_mm_table(kinect.get("depth_model", {"kind": "zero-plane"}))

    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        check(header.profile == "ros2", f"profile {header.profile!r}, not ros2")
        summary = reader.get_summary()
        check(summary is not None, "no summary section")
        check(summary.statistics is not None, "no statistics in the summary")
        check(len(summary.chunk_indexes) > 0, "no chunk indexes")
        check(all(c.message_index_offsets for c in summary.chunk_indexes), "a chunk without message indexes")
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            check(schema is not None, f"{channel.topic}: no schema")
            check(schema.encoding == "ros2msg", f"{channel.topic}: schema encoding {schema.encoding}")
            check(channel.message_encoding == "cdr", f"{channel.topic}: message encoding {channel.message_encoding}")
        static = [c for c in summary.channels.values() if c.topic == "/tf_static"]
        check(len(static) == 1 and "durability: 1" in static[0].metadata.get("offered_qos_profiles", ""),
              "/tf_static is not offered transient local")

        counts = {}
        last_time = 0
        frames = iter([(name, pose) for pose in poses for name in pose["depth_frames"]])
        images_compared = 0
        tf_static = None
        bodies = {}
        fits = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            topic = channel.topic
            counts[topic] = counts.get(topic, 0) + 1
            check(message.log_time >= last_time, f"{topic}: log time goes back")
            last_time = message.log_time
            stamp = getattr(decoded, "header", None)
            if stamp is not None:
                stamp_ns = stamp.stamp.sec * 10**9 + stamp.stamp.nanosec
                check(stamp_ns == message.log_time, f"{topic}: header stamp {stamp_ns} against log time {message.log_time}")
            if topic == "/camera/depth/raw_11bit":
                name, pose = next(frames)
                check(message.log_time == frame_time_ns(name), f"{name}: stamped {message.log_time}")
                raw = read_raw(recording / "kinect" / name, width, height)
                check(decoded.encoding == "mono16" and decoded.width == width and decoded.height == height,
                      f"{name}: raw image {decoded.encoding} {decoded.width}x{decoded.height}")
                check(struct.unpack(f"<{width * height}H", bytes(decoded.data)) == raw, f"{name}: raw values differ")
                expected_mm = [millimetres[v] for v in raw]
            elif topic == "/camera/depth/image_raw":
                check(decoded.encoding == "16UC1" and decoded.step == 2 * width and decoded.is_bigendian == 0,
                      f"{name}: depth image {decoded.encoding} step {decoded.step}")
                check(decoded.header.frame_id == OPTICAL, f"depth frame_id {decoded.header.frame_id}")
                mm = struct.unpack(f"<{width * height}H", bytes(decoded.data))
                if list(mm) != expected_mm:
                    bad = next(i for i, (a, b) in enumerate(zip(mm, expected_mm)) if a != b)
                    fail(f"{name}: pixel {bad}: {mm[bad]} mm, the depth model gives {expected_mm[bad]}")
                images_compared += 1
            elif topic == "/camera/depth/camera_info":
                k = list(decoded.k)
                check(k == [intrinsics["fx"], 0, intrinsics["cx"], 0, intrinsics["fy"], intrinsics["cy"], 0, 0, 1],
                      f"camera_info k {k}")
            elif topic == "/tf_static":
                check(len(decoded.transforms) == 1, "/tf_static holds one transform")
                tf_static = decoded.transforms[0]
            elif topic == "/tf":
                for t in decoded.transforms:
                    if t.header.frame_id == "ground" and t.child_frame_id == "base_link":
                        bodies[message.log_time] = t.transform
                feet = [t for t in decoded.transforms if t.child_frame_id.startswith("foot_")]
                check(len(feet) == 6, f"/tf at {message.log_time}: {len(feet)} feet")
            elif topic == "/groundcal/pose_fit":
                fits[decoded.pose_index] = (message.log_time, decoded)
            elif topic.startswith("/groundcal/ground/"):
                check(decoded.width > 0 and len(decoded.data) == decoded.width * decoded.point_step,
                      f"{topic}: {decoded.width} points, {len(decoded.data)} bytes")

        total_frames = sum(len(p["depth_frames"]) for p in poses)
        for topic in ("/camera/depth/image_raw", "/camera/depth/raw_11bit", "/camera/depth/camera_info"):
            check(counts.get(topic, 0) == total_frames, f"{topic}: {counts.get(topic, 0)} messages, {total_frames} frames")
        check(counts.get("/tf_static") == 1, "one /tf_static")
        check(counts.get("/groundcal/pose_fit") == len(poses), f"{counts.get('/groundcal/pose_fit')} pose fits, {len(poses)} poses")
        check(summary.statistics.message_count == sum(counts.values()), "statistics' message count")

        # The TF chain base_link -> camera_depth_optical_frame gives back the
        # calibrated robot_from_sensor (millimetres in the result).
        expected = result["robot_from_sensor"]["matrix"]
        base_from_optical = homogeneous(tf_static.transform)
        robot_from_sensor = matmul(matmul(transpose(ROS_FROM_GROUNDCAL), base_from_optical), transpose(SENSOR_FROM_OPTICAL))
        mount_error = max(
            abs(robot_from_sensor[i][j] - expected[i][j] / (1000.0 if j == 3 and i < 3 else 1.0))
            for i in range(3) for j in range(4))
        check(mount_error < 1e-6, f"the TF chain's mount is {mount_error} off the result's")

        # Per pose, ground -> base_link -> optical gives the ground the result
        # predicts in the sensor frame (its plane: row Y of ground_from_sensor).
        plane_error = 0.0
        planes_compared = 0
        for pose in result["poses"]:
            predicted = pose.get("predicted_plane")
            fit = fits.get(pose["index"])
            check(fit is not None, f"pose {pose['index']}: no pose_fit")
            if pose.get("theta_deg") is not None:
                check(abs(fit[1].theta_deg - pose["theta_deg"]) < 1e-12, f"pose {pose['index']}: θ")
                check(abs(fit[1].e_d_mm - pose["e_d_mm"]) < 1e-12, f"pose {pose['index']}: e_d")
            check(fit[1].used == pose["used"], f"pose {pose['index']}: used")
            if predicted is None:
                continue
            # The pose's body: the last /tf at or before its fit.
            before = [time for time in bodies if time <= fit[0]]
            check(before, f"pose {pose['index']}: no body pose before its fit")
            ground_from_body = homogeneous(bodies[max(before)])
            ground_from_sensor = matmul(matmul(matmul(transpose(ROS_FROM_GROUNDCAL), ground_from_body), base_from_optical),
                                        transpose(SENSOR_FROM_OPTICAL))
            row = ground_from_sensor[1]
            plane = [predicted["a"], predicted["b"], predicted["c"], predicted["d_m"]]
            plane_error = max(plane_error, max(abs(a - b) for a, b in zip(row, plane)))
            planes_compared += 1
        check(plane_error < 1e-6, f"the TF chain's ground is {plane_error} off the predicted planes")

        attachments = {a.name: a for a in reader.iter_attachments()}
        check("result.json" in attachments, "no result.json attachment")
        attached = json.loads(attachments["result.json"].data)
        check(attached["robot_from_sensor"] == result["robot_from_sensor"], "the attached result differs")
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        check(metadata.get("groundcal", {}).get("status") == result["status"], "metadata status")

    print(json.dumps({
        "counts": counts,
        "frames": total_frames,
        "images_compared": images_compared,
        "mount_error": mount_error,
        "planes_compared": planes_compared,
        "plane_error": plane_error,
        "chunks": len(summary.chunk_indexes),
    }))


if __name__ == "__main__":
    main()
