"""The ROS 2 node (``python -m qtvpr.ros``) on a real ROS 2 graph.

The node runs as a subprocess on a random ``ROS_DOMAIN_ID``, discovery limited to this
machine; the test publishes the Corridor deployment columns to it and compares every
decision with ``qtvpr-cli stream`` on the same columns, bit for bit, with malformed
messages among them. Skipped where ROS 2 Jazzy's Python packages are not installed
(``pip install ".[ros]"``: wheels for CPython 3.11 only).
"""

from __future__ import annotations

import array
import json
import math
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

try:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Bool, Float32MultiArray, Float64MultiArray
except ImportError as err:
    pytest.skip(
        f'ROS 2 Jazzy not installed ({err}); pip install ".[ros]" (wheels for CPython 3.11 only)',
        allow_module_level=True,
    )

import qtvpr
from qtvpr.ros import DECISION_FIELDS

CORRIDOR = Path(__file__).resolve().parents[1] / "data" / "corridor"

# Far above the Corridor's 100 queries: the burst of messages is never cut.
DEPTH = 1000
QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=DEPTH)


@pytest.fixture(scope="module")
def ros_env() -> Iterator[dict[str, str]]:
    """A random domain, discovery on this machine only, for the node and the test."""
    saved = {k: os.environ.get(k) for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 100))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    yield dict(os.environ)
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@pytest.fixture(scope="module")
def cal(tmp_path_factory: pytest.TempPathFactory, cli: Path) -> Path:
    """A calibration file of the Corridor's calibration traverse, window 10."""
    path = tmp_path_factory.mktemp("ros") / "cal.npz"
    subprocess.run(
        [cli, "calibrate", "--cal", CORRIDOR / "cal_S.npy", "--cal-gt", CORRIDOR / "cal_GT.npy",
         "--window", "10", "--output", path],
        check=True,
    )
    return path


def node(cal: Path, env: dict[str, str], *params: str) -> subprocess.Popen[str]:
    args = ["-p", f"calibration:={cal}"] + [a for p in params for a in ("-p", p)]
    return subprocess.Popen(
        [sys.executable, "-m", "qtvpr.ros", "--ros-args", *args],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )


def stop(proc: subprocess.Popen[str]) -> str:
    """Stop the node with Ctrl-C; its log. A clean exit is status 0."""
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    return err


def expected(cli: Path, cal: Path, val: Path, *flags: str) -> list[list[float]]:
    """``stream``'s decisions of ``val``, laid out as ``~/decision`` lays them out."""
    out = subprocess.run(
        [cli, "stream", "--calibration", cal, "--val", val, *flags], check=True, capture_output=True, text=True
    ).stdout
    lines = [json.loads(line) for line in out.splitlines()]
    return [[float(rec[f]) if f in rec else math.nan for f in DECISION_FIELDS] for rec in lines]


class Client:
    """The test's own node: publishes scores to the qtvpr node and collects decisions."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("qtvpr_test", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.scores = self.node.create_publisher(Float32MultiArray, "/qtvpr/scores", QOS)
        self.scores64 = self.node.create_publisher(Float64MultiArray, "/qtvpr/scores64", QOS)
        self.decisions: list[Float64MultiArray] = []
        self.accepts: list[bool] = []
        self.sub = self.node.create_subscription(Float64MultiArray, "/qtvpr/decision", self.decisions.append, QOS)
        self.sub_accept = self.node.create_subscription(
            Bool, "/qtvpr/accept", lambda m: self.accepts.append(m.data), QOS
        )

    def spin_until(self, done, what: str, timeout: float = 30.0) -> None:  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            self.executor.spin_once(timeout_sec=0.05)

    def wait_for(self, proc: subprocess.Popen[str]) -> None:
        """Until the node's topics are matched both ways."""

        def matched() -> bool:
            assert proc.poll() is None, proc.communicate()[1]
            return (
                self.scores.get_subscription_count() > 0
                and self.scores64.get_subscription_count() > 0
                and self.sub.get_publisher_count() > 0
                and self.sub_accept.get_publisher_count() > 0
            )

        self.spin_until(matched, "the node's topics")

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def client(ros_env: dict[str, str]) -> Iterator[Client]:
    c = Client()
    yield c
    c.close()


def f32(column: np.ndarray) -> Float32MultiArray:
    return Float32MultiArray(data=array.array("f", np.ascontiguousarray(column, dtype=np.float32).tobytes()))


def f64(column: np.ndarray) -> Float64MultiArray:
    return Float64MultiArray(data=array.array("d", np.ascontiguousarray(column, dtype=np.float64).tobytes()))


def check_decisions(client: Client, want: list[list[float]]) -> None:
    client.spin_until(lambda: len(client.decisions) >= len(want) and len(client.accepts) >= len(want), "decisions")
    time.sleep(0.5)  # nothing more comes
    for _ in range(10):
        client.executor.spin_once(timeout_sec=0.01)
    assert len(client.decisions) == len(want)
    assert len(client.accepts) == len(want)
    for j, (msg, row) in enumerate(zip(client.decisions, want, strict=True)):
        (dim,) = msg.layout.dim
        n = len(DECISION_FIELDS)
        assert (dim.label, dim.size, dim.stride) == (",".join(DECISION_FIELDS), n, n)
        # Bit for bit, NaN (no gate) included.
        assert np.asarray(msg.data).tobytes() == np.asarray(row).tobytes(), (j, list(msg.data), row)
        assert client.accepts[j] == bool(row[DECISION_FIELDS.index("accept")])


def test_decision_fields_are_the_cores() -> None:
    assert DECISION_FIELDS == (
        "query", "query_quantile", "weight", "quantile", "threshold", "best", "score", "accepted", "accept",
        "confidence", "confidence_lower95", "margin", "gate",
    )
    assert qtvpr.OnlineDecision.FIELDS + qtvpr.OnlineDecision.GATE_FIELDS == DECISION_FIELDS


def test_float32_scores_decided_as_stream_with_bad_messages(
    client: Client, ros_env: dict[str, str], cal: Path, cli: Path, tmp_path: Path
) -> None:
    s_val = np.load(CORRIDOR / "deploy_S.npy").astype(np.float32)
    val = tmp_path / "deploy_S32.npy"
    np.save(val, s_val)
    want = expected(cli, cal, val)
    assert len(want) == 100

    proc = node(cal, ros_env, f"qos_depth:={DEPTH}")
    client.wait_for(proc)
    nan = s_val[:, 30].copy()
    nan[7] = np.nan
    inf = s_val[:, 40].copy()
    inf[3] = np.inf
    bad = {10: f32(np.zeros(0)), 20: f32(s_val[:110, 20]), 30: f32(nan), 40: f32(inf)}
    for j in range(s_val.shape[1]):
        if j in bad:
            client.scores.publish(bad[j])
        client.scores.publish(f32(s_val[:, j]))
    check_decisions(client, want)
    log = stop(proc)

    errors = [line for line in log.splitlines() if "[ERROR]" in line]
    assert len(errors) == 4, log
    # Message numbers count every message; the queries decided before each bad one.
    assert "scores message 11 (float32, 0 scores; 10 queries decided): column: deployment query 10 has 0" in errors[0]
    assert "scores message 22 (float32, 110 scores; 20 queries decided)" in errors[1]
    assert "has 110 scores but the calibration has 111 database images" in errors[1]
    assert "message 33 (float32, 111 scores; 30 queries decided)" in errors[2]
    assert "column (deployment query 30) contains NaN at row 7" in errors[2]
    assert "message 44 (float32, 111 scores; 40 queries decided)" in errors[3]
    assert "column (deployment query 40) contains inf at row 3" in errors[3]
    assert all("not decided, the window is unchanged" in e for e in errors)


def test_float64_scores_with_parameters_and_gate(
    client: Client, ros_env: dict[str, str], cal: Path, cli: Path
) -> None:
    val = CORRIDOR / "deploy_S.npy"
    s_val = np.load(val)
    assert s_val.dtype == np.float64
    want = expected(cli, cal, val, "--window", "5", "--min-window", "3", "--gate", "margin", "--k", "4")
    assert not math.isnan(want[0][DECISION_FIELDS.index("gate")])

    proc = node(cal, ros_env, "window:=5", "min_window:=3", "gate:=margin", "k:=4", f"qos_depth:={DEPTH}")
    client.wait_for(proc)
    for j in range(s_val.shape[1]):
        if j == 50:
            client.scores64.publish(f64(np.r_[s_val[:, j], 0.5]))
        client.scores64.publish(f64(s_val[:, j]))
    check_decisions(client, want)
    log = stop(proc)
    (error,) = [line for line in log.splitlines() if "[ERROR]" in line]
    assert "scores message 51 (float64, 112 scores; 50 queries decided): column: deployment query 50 has 112" in error
    assert "Online(k=4, precision=1.0, window=5, min_window=3, gate='margin'" in log


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ((), "parameter calibration (a calibration file, .npz) is required"),
        (("calibration:={tmp}/absent.npz",), "absent.npz: cannot read"),
        (("calibration:={tmp}/corrupt.npz",), "corrupt.npz is not a valid .npz archive"),
        (("calibration:={cal}", "k:=0"), "parameters {'k': 0}: k must be >= 1, got 0"),
        (("calibration:={cal}", "window:=4", "min_window:=5"), "min_window"),
        (("calibration:={cal}", "gate:=fast"), "gate"),
        (("calibration:={cal}", "qos_depth:=0"), "parameter qos_depth must be an integer of at least 1, not 0"),
    ],
)
def test_start_up_errors_exit_1(
    ros_env: dict[str, str], cal: Path, tmp_path: Path, params: tuple[str, ...], message: str
) -> None:
    (tmp_path / "corrupt.npz").write_bytes(b"not a zip archive")
    args = [a for p in params for a in ("-p", p.format(tmp=tmp_path, cal=cal))]
    proc = subprocess.run(
        [sys.executable, "-m", "qtvpr.ros", "--ros-args", *args],
        env=ros_env, capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 1, proc.stderr
    (line,) = [line for line in proc.stderr.splitlines() if "[ERROR]" in line]
    assert "[qtvpr]: cannot start: " in line
    assert message in line, line
