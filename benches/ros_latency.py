"""Publish-to-decision latency of the ROS 2 node (``python -m qtvpr.ros``).

What a robot's graph sees: the time from a matcher's ``publish`` of one query's scores
to the arrival of its decision, through Fast DDS between two processes of this machine,
on each of the node's two interfaces: *array*, ``/qtvpr/scores``
(``std_msgs/Float32MultiArray``) to ``/qtvpr/decision`` (``Float64MultiArray``), and
*typed*, ``/qtvpr/scores_msg`` (``qtvpr_msgs/Scores``) to ``/qtvpr/decision_msg``
(``qtvpr_msgs/Decision``); the same node decides both, one after the other. The node
runs as a subprocess on a random ``ROS_DOMAIN_ID`` (discovery on localhost only); one
message is in flight at a time, so each figure is one query's latency, not a queue's.
Beside it, ``qtvpr.Online.push`` alone on the same columns in this process: the share
of the latency that deciding takes (the rest is serialisation, DDS and rclpy's
executor). Cases:

1. Corridor (real, data/corridor): |DB| = 111, window 10, its 100 deployment columns
   sent three times over (300 messages);
2. Nordland HOG (real, ../shared/data/nordland-hog, when present): |DB| = 3576, the first
   357 queries calibrate, window 36; 1000 messages;
3. Nordland at paper scale (synthetic, benches/synthetic.py): |DB| = 27592, 276
   calibration queries, window 28; 500 messages.

Reported: median and 99th percentile over the messages after the window first fills,
each topic's, and its median's ratio to the push's (the issue's target: at most 2x).

    python benches/ros_latency.py [--no-readme] [--cases corridor,nordland,paper]

Writes the table into docs/deployment.md between <!-- ros-bench:start --> and
<!-- ros-bench:end -->. Needs the wheel with its ROS extra and the interface package
(pip install ".[ros]" ./ros/qtvpr_msgs).
"""

from __future__ import annotations

import argparse
import array
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import qtvpr

os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 100))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

import rclpy  # noqa: E402
from qtvpr_msgs.msg import Decision, Scores  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import Float32MultiArray, Float64MultiArray, Header  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))  # shared_data: the data
from online_latency import synthetic_case  # noqa: E402
from report import machine, write_block  # noqa: E402
from shared_data import nordland_similarity  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=100)


def stamper(arrived: list[int]):  # type: ignore[no-untyped-def]
    """A callback that appends each message's arrival time to ``arrived``."""
    return lambda _: arrived.append(time.perf_counter_ns())


def measure(name: str, s_cal: np.ndarray, gt_cal: np.ndarray, s_val: np.ndarray, window: int, n: int) -> dict:
    """Latencies (ms) of ``n`` messages on each interface, the columns of ``s_val`` in
    turn, float32; and of ``n`` pushes of the same columns."""
    columns = [np.ascontiguousarray(s_val[:, j % s_val.shape[1]], dtype=np.float32) for j in range(n)]
    cal = qtvpr.Calibration(s_cal, gt_cal)
    online = qtvpr.Online(cal, k=10, precision=1.0, window=window)
    push = []
    for c in columns:
        t = time.perf_counter_ns()
        online.push(c)
        push.append(time.perf_counter_ns() - t)

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cal.npz"
        cal.save(path, k=10, precision=1.0, window=window)
        proc = subprocess.Popen(
            [sys.executable, "-m", "qtvpr.ros", "--ros-args", "-p", f"calibration:={path}"],
            stdout=subprocess.DEVNULL,
        )
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node("qtvpr_bench", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        # One interface at a time, as its user sees it: only its decision topic is
        # subscribed (rclpy's executor runs one callback per spin, so a second one would
        # delay the first's arrival).
        interfaces = {
            "array": (Float32MultiArray, "/qtvpr/scores", Float64MultiArray, "/qtvpr/decision"),
            "typed": (Scores, "/qtvpr/scores_msg", Decision, "/qtvpr/decision_msg"),
        }
        latency: dict[str, list[int]] = {}
        for kind, (in_type, in_topic, out_type, out_topic) in interfaces.items():
            arrived: list[int] = []
            pub = node.create_publisher(in_type, in_topic, QOS)
            sub = node.create_subscription(out_type, out_topic, stamper(arrived), QOS)
            while pub.get_subscription_count() == 0 or sub.get_publisher_count() == 0:
                if proc.poll() is not None:
                    sys.exit(f"the node exited with status {proc.returncode}")
                executor.spin_once(timeout_sec=0.05)
            latency[kind] = []
            for c in columns:
                if kind == "array":
                    msg = Float32MultiArray(data=array.array("f", c.tobytes()))
                else:
                    stamp = node.get_clock().now().to_msg()
                    msg = Scores(header=Header(stamp=stamp), scores=array.array("f", c.tobytes()))
                count = len(arrived)
                t = time.perf_counter_ns()
                pub.publish(msg)
                while len(arrived) == count:
                    executor.spin_once(timeout_sec=1.0)
                latency[kind].append(arrived[-1] - t)
            node.destroy_subscription(sub)
            node.destroy_publisher(pub)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)

    def ms(values: list[int]) -> np.ndarray:
        return np.array(values[window:], dtype=np.float64) / 1e6

    row = {"name": name, "db": s_cal.shape[0], "cal": s_cal.shape[1], "window": window, "messages": n - window}
    steady_push = ms(push)
    row["push"], row["push99"] = float(np.median(steady_push)), float(np.percentile(steady_push, 99))
    for kind, values in latency.items():
        steady = ms(values)
        row[kind], row[f"{kind}99"] = float(np.median(steady)), float(np.percentile(steady, 99))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--no-readme", action="store_true", help="print only; leave docs/deployment.md alone")
    ap.add_argument("--cases", default="corridor,nordland,paper", help="comma-separated: corridor, nordland, paper")
    args = ap.parse_args()
    cases = set(args.cases.split(","))

    rows = []
    if "corridor" in cases:
        corridor = REPO / "data" / "corridor"
        s_cal, gt_cal = np.load(corridor / "cal_S.npy"), np.load(corridor / "cal_GT.npy")
        rows.append(measure("Corridor (real)", s_cal, gt_cal, np.load(corridor / "deploy_S.npy"), 10, 300))
    if "nordland" in cases and (SHARED / "nordland-hog").is_dir():
        s, gt = nordland_similarity(SHARED)
        n_cal = s.shape[1] // 10
        rows.append(measure("Nordland HOG (real)", s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:], 36, 1000))
    if "paper" in cases:
        with tempfile.TemporaryDirectory() as tmp:
            s_cal, gt_cal, s_val = synthetic_case(Path(tmp), 27592, 2760, 500)
            rows.append(measure("Nordland, paper scale (synthetic)", s_cal, gt_cal, s_val, 28, 500))

    load = os.getloadavg()[0]
    lines = [
        f"Measured by `benches/ros_latency.py` on {machine()} (1-minute load average {load:.1f} at the "
        "end: other processes shared the cores), ROS 2 Jazzy (rclpy, Fast DDS, from PyPI), "
        "the node and the publisher in two processes, discovery on localhost; float32 columns, k = 10, "
        "tau = 1, one message in flight; the messages after the window first fills, on each interface: "
        "*array* (`~/scores` to `~/decision`, `std_msgs`) and *typed* (`~/scores_msg` to `~/decision_msg`, "
        "`qtvpr_msgs`). *push* is `qtvpr.Online.push` alone on the same columns, in the publisher's "
        "process (a push runs on the calling thread); *x push*: a median over the push's, same run. "
        "Corridor's push is negligible: its row is the floor of two rclpy executors and Fast DDS.",
        "",
        "| case | \\|DB\\| | calibration queries | window | messages | push: median (99th pct.) "
        "| array: median (99th pct.) | x push | typed: median (99th pct.) | x push |",
        "|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['db']} | {r['cal']} | {r['window']} | {r['messages']} "
            f"| {r['push']:.3f} ms ({r['push99']:.3f}) "
            f"| {r['array']:.3f} ms ({r['array99']:.3f}) | {r['array'] / r['push']:.1f}x "
            f"| {r['typed']:.3f} ms ({r['typed99']:.3f}) | {r['typed'] / r['push']:.1f}x |"
        )
    text = "\n".join(lines)
    print(text)
    if not args.no_readme:
        write_block(REPO / "docs" / "deployment.md", "ros-bench", text)


if __name__ == "__main__":
    main()
