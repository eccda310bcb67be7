"""The ROS 2 node (``python -m qtvpr.ros``) on a real ROS 2 graph.

The node runs as a subprocess on a random ``ROS_DOMAIN_ID``, discovery limited to this
machine; the test publishes the Corridor deployment columns to it and compares every
decision, on each of its three output topics, with ``qtvpr-cli stream`` on the same
columns, bit for bit, with malformed messages among them; the typed ``qtvpr_msgs``
topics carry the input's header. Skipped where ROS 2 Jazzy's Python packages and
qtvpr_msgs are not installed (``pip install ".[ros]" ./ros/qtvpr_msgs``: wheels for
CPython 3.11 only).
"""

from __future__ import annotations

import array
import json
import math
import os
import random
import shlex
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
    import yaml
    from builtin_interfaces.msg import Time
    from qtvpr_msgs.msg import Decision, Scores
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Bool, Float32MultiArray, Float64MultiArray, Header
except ImportError as err:
    pytest.skip(
        f'ROS 2 Jazzy or qtvpr_msgs not installed ({err}); pip install ".[ros]" ./ros/qtvpr_msgs '
        "(wheels for CPython 3.11 only)",
        allow_module_level=True,
    )

import qtvpr
from qtvpr.ros import DECISION_FIELDS, DECISION_MSG_FIELDS

REPO = Path(__file__).resolve().parents[1]
CORRIDOR = REPO / "data" / "corridor"

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
    return calibrate(cli, tmp_path_factory.mktemp("ros") / "cal.npz")


def calibrate(cli: Path, path: Path, *flags: str) -> Path:
    """``path``: a calibration file of the Corridor's calibration traverse, window 10,
    with ``flags``."""
    subprocess.run(
        [cli, "calibrate", "--cal", CORRIDOR / "cal_S.npy", "--cal-gt", CORRIDOR / "cal_GT.npy",
         "--window", "10", *flags, "--output", path],
        check=True,
    )
    return path


def node(cal: Path, env: dict[str, str], *params: str, remap: tuple[str, ...] = ()) -> subprocess.Popen[str]:
    args = ["-p", f"calibration:={cal}"] + [a for p in params for a in ("-p", p)]
    args += [a for r in remap for a in ("-r", r)]
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
    # A field that does not apply: absent (no gate) or null (confidence, multi matching).
    return [[math.nan if rec.get(f) is None else float(rec[f]) for f in DECISION_FIELDS] for rec in lines]


class Client:
    """The test's own node: publishes scores to the qtvpr node (``/qtvpr`` unless
    ``base`` says otherwise) and collects its decisions from all three topics."""

    def __init__(self, base: str = "/qtvpr") -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("qtvpr_test", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.scores = self.node.create_publisher(Float32MultiArray, f"{base}/scores", QOS)
        self.scores64 = self.node.create_publisher(Float64MultiArray, f"{base}/scores64", QOS)
        self.scores_msg = self.node.create_publisher(Scores, f"{base}/scores_msg", QOS)
        self.decisions: list[Float64MultiArray] = []
        self.accepts: list[bool] = []
        self.typed: list[Decision] = []
        self.subs = [
            self.node.create_subscription(Float64MultiArray, f"{base}/decision", self.decisions.append, QOS),
            self.node.create_subscription(Bool, f"{base}/accept", lambda m: self.accepts.append(m.data), QOS),
            self.node.create_subscription(Decision, f"{base}/decision_msg", self.typed.append, QOS),
        ]

    def spin_until(self, done, what: str, timeout: float = 30.0) -> None:  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            self.executor.spin_once(timeout_sec=0.05)

    def wait_for(self, proc: subprocess.Popen[str]) -> None:
        """Until the node's topics are matched both ways."""

        def matched() -> bool:
            assert proc.poll() is None, proc.communicate()[1]
            return all(p.get_subscription_count() > 0 for p in (self.scores, self.scores64, self.scores_msg)) and all(
                s.get_publisher_count() > 0 for s in self.subs
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


def scores_msg(column: np.ndarray | None, header: Header, column64: np.ndarray | None = None) -> Scores:
    """A ``qtvpr_msgs/Scores``: ``column`` in its own type's array (and ``column64`` in
    ``scores64``, to build a malformed message with both)."""
    msg = Scores(header=header)
    if column is not None:
        if column.dtype == np.float32:
            msg.scores = array.array("f", column.tobytes())
        else:
            msg.scores64 = array.array("d", column.tobytes())
    if column64 is not None:
        msg.scores64 = array.array("d", column64.astype(np.float64).tobytes())
    return msg


def stamped(j: int) -> Header:
    """The header of query ``j``: a stamp and a frame of its own."""
    return Header(stamp=Time(sec=1_700_000_000 + j, nanosec=(7919 * j) % 1_000_000_000), frame_id=f"camera_{j}")


def check_decisions(
    client: Client,
    want: list[list[float]],
    headers: list[Header] | None = None,
    accepted_indices: list[list[int]] | None = None,
) -> None:
    """The node's decisions on all three topics are ``want`` (``stream``'s), bit for bit;
    the typed ones carry ``headers`` and ``accepted_indices`` when given (single
    matching: the best match, if accepted)."""
    n = len(want)
    client.spin_until(lambda: min(len(client.decisions), len(client.accepts), len(client.typed)) >= n, "decisions")
    time.sleep(0.5)  # nothing more comes
    for _ in range(10):
        client.executor.spin_once(timeout_sec=0.01)
    assert (len(client.decisions), len(client.accepts), len(client.typed)) == (n, n, n)
    fields = len(DECISION_FIELDS)
    for j, (msg, typed, row) in enumerate(zip(client.decisions, client.typed, want, strict=True)):
        (dim,) = msg.layout.dim
        assert (dim.label, dim.size, dim.stride) == (",".join(DECISION_FIELDS), fields, fields)
        # Bit for bit, NaN (no gate) included.
        assert np.asarray(msg.data).tobytes() == np.asarray(row).tobytes(), (j, list(msg.data), row)
        assert client.accepts[j] == bool(row[DECISION_FIELDS.index("accept")])
        # The typed decision: every field, in its own type, the same value.
        got = [float(getattr(typed, f)) for f in DECISION_FIELDS]
        assert np.asarray(got).tobytes() == np.asarray(row).tobytes(), (j, got, row)
        assert isinstance(typed.query, int) and isinstance(typed.accept, bool)
        if accepted_indices is None:
            best = int(row[DECISION_FIELDS.index("best")])
            assert list(typed.accepted_indices) == ([best] if typed.accept else [])
        else:
            assert list(typed.accepted_indices) == accepted_indices[j], j
    if headers is not None:
        assert [t.header.frame_id for t in client.typed] == [h.frame_id for h in headers]
        stamps = [(t.header.stamp.sec, t.header.stamp.nanosec) for t in client.typed]
        assert stamps == [(h.stamp.sec, h.stamp.nanosec) for h in headers]


def assert_arrival_headers(typed: list[Decision], start: float, end: float) -> None:
    """The headers of decisions of array messages: no frame; the node's clock when each
    arrived, between ``start`` and ``end`` (this machine's clock), rising."""
    stamps = [t.header.stamp.sec + t.header.stamp.nanosec * 1e-9 for t in typed]
    assert all(t.header.frame_id == "" for t in typed)
    assert stamps == sorted(stamps) and start - 1 <= stamps[0] and stamps[-1] <= end + 1, (start, stamps, end)


def test_decision_fields_are_the_cores() -> None:
    assert DECISION_FIELDS == (
        "query", "query_quantile", "weight", "quantile", "threshold", "best", "score", "accepted", "accept",
        "confidence", "confidence_lower95", "margin", "gate", "consistency", "consistency_level",
    )
    online = qtvpr.OnlineDecision
    assert online.FIELDS + online.GATE_FIELDS + online.SEQUENCE_FIELDS == DECISION_FIELDS


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
    start = time.time()
    for j in range(s_val.shape[1]):
        if j in bad:
            client.scores.publish(bad[j])
        client.scores.publish(f32(s_val[:, j]))
    check_decisions(client, want)
    assert_arrival_headers(client.typed, start, time.time())
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

    proc = node(cal, ros_env, "window:=5", "min_window:=3", "gate:=margin", "k:=4", f"qos_depth:={DEPTH}",
                "use_sim_time:=false")  # a parameter every node has: not refused
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


def test_sequence_matched_file_with_both_gates_is_stream(
    client: Client, ros_env: dict[str, str], cli: Path, tmp_path: Path
) -> None:
    """A calibration file of L = 3 (§15): the node decides each query on its causal
    sequence-matched column, with the margin and sequence gates and its own sequence
    parameters, as ``stream`` does with the same options."""
    cal = calibrate(cli, tmp_path / "seq.npz", "--sequence", "3")
    val = CORRIDOR / "deploy_S.npy"
    s_val = np.load(val)
    want = expected(cli, cal, val, "--gate", "margin,sequence", "--sequence-window", "4", "--sequence-level", "0.75")
    consistency = [row[DECISION_FIELDS.index("consistency")] for row in want]
    assert all(row[DECISION_FIELDS.index("consistency_level")] == 0.75 for row in want)
    # The first query has no past (§15: consistency 0); later ones are shares of 4.
    assert consistency[0] == 0 and {c * 4 for c in consistency[4:]} <= {0, 1, 2, 3, 4}, consistency
    # The gates decide: some best matches above the threshold are not kept.
    over = [row for row in want if row[DECISION_FIELDS.index("score")] >= row[DECISION_FIELDS.index("threshold")]]
    assert any(row[DECISION_FIELDS.index("accept")] == 0 for row in over)

    proc = node(cal, ros_env, "gate:=margin,sequence", "sequence_window:=4", "sequence_level:=0.75",
                f"qos_depth:={DEPTH}")
    client.wait_for(proc)
    for j in range(s_val.shape[1]):
        client.scores64.publish(f64(s_val[:, j]))
    check_decisions(client, want)
    log = stop(proc)
    assert "[ERROR]" not in log, log


def test_decision_msg_is_the_record() -> None:
    """The generated qtvpr_msgs/Decision has the record's fields (tests/test_ros_msgs.py
    holds the .msg file to the core's lists), and is built from this tree's file."""
    assert tuple(Decision.get_fields_and_field_types()) == DECISION_MSG_FIELDS
    assert DECISION_MSG_FIELDS == ("header", *DECISION_FIELDS, "accepted_indices")
    for name in ("Decision", "Scores"):
        installed = Path(sys.prefix) / "share" / "qtvpr_msgs" / "msg" / f"{name}.msg"
        mine = REPO / "ros" / "qtvpr_msgs" / "msg" / f"{name}.msg"
        assert installed.read_text() == mine.read_text(), f"{installed} is stale: pip install ./ros/qtvpr_msgs"


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_typed_scores_decided_as_stream_with_their_headers(
    client: Client, ros_env: dict[str, str], cal: Path, cli: Path, tmp_path: Path, dtype: type
) -> None:
    s_val = np.load(CORRIDOR / "deploy_S.npy").astype(dtype)
    val = tmp_path / "deploy_S.npy"
    np.save(val, s_val)
    want = expected(cli, cal, val)
    assert len(want) == 100

    proc = node(cal, ros_env, f"qos_depth:={DEPTH}")
    client.wait_for(proc)
    nan = s_val[:, 30].copy()
    nan[7] = np.nan
    bad = {
        10: scores_msg(None, stamped(-10)),  # neither array
        20: scores_msg(s_val[:, 20].astype(np.float32), stamped(-20), s_val[:, 20]),  # both
        30: scores_msg(nan, stamped(-30)),
        40: scores_msg(s_val[:110, 40], stamped(-40)),
    }
    headers = [stamped(j) for j in range(s_val.shape[1])]
    for j in range(s_val.shape[1]):
        if j in bad:
            client.scores_msg.publish(bad[j])
        client.scores_msg.publish(scores_msg(s_val[:, j], headers[j]))
    check_decisions(client, want, headers)
    log = stop(proc)

    errors = [line for line in log.splitlines() if "[ERROR]" in line]
    assert len(errors) == 4, log
    name = np.dtype(dtype).name
    assert (
        "scores message 11 (qtvpr_msgs/Scores, stamp 1699999990.999920810; 10 queries decided): exactly one "
        "of scores (float32) and scores64 (float64) must hold the column, not 0 and 0 scores" in errors[0]
    )
    assert "scores message 22 (qtvpr_msgs/Scores, stamp 1699999980.999841620; 20 queries decided)" in errors[1]
    assert "not 111 and 111 scores" in errors[1]
    assert f"scores message 33 ({name}, 111 scores, stamp 1699999970.999762430; 30 queries decided)" in errors[2]
    assert "column (deployment query 30) contains NaN at row 7" in errors[2]
    assert f"scores message 44 ({name}, 110 scores, stamp 1699999960.999683240; 40 queries decided)" in errors[3]
    assert "has 110 scores but the calibration has 111 database images" in errors[3]
    assert all("not decided, the window is unchanged" in e for e in errors)


def test_typed_decisions_of_multi_matching(
    client: Client, ros_env: dict[str, str], cli: Path, tmp_path: Path
) -> None:
    """Multi matching: every accepted index, and a NaN confidence (stream's null)."""
    cal = calibrate(cli, tmp_path / "multi.npz", "--matching", "multi")
    val = CORRIDOR / "deploy_S.npy"
    s_val = np.load(val)
    want = expected(cli, cal, val)
    online = qtvpr.Online(qtvpr.Calibration.load(cal))
    indices = [online.push(s_val[:, j]).accepted_indices.tolist() for j in range(s_val.shape[1])]
    assert max(len(i) for i in indices) > 1 and math.isnan(want[0][DECISION_FIELDS.index("confidence")])

    proc = node(cal, ros_env, f"qos_depth:={DEPTH}")
    client.wait_for(proc)
    headers = [stamped(j) for j in range(s_val.shape[1])]
    for j in range(s_val.shape[1]):
        client.scores_msg.publish(scores_msg(s_val[:, j], headers[j]))
    check_decisions(client, want, headers, indices)
    stop(proc)
    for j, typed in enumerate(client.typed):
        column = s_val[:, j]
        assert list(typed.accepted_indices) == np.flatnonzero(column >= typed.threshold).tolist()
        assert typed.accepted == len(typed.accepted_indices)


def test_array_and_typed_topics_feed_one_stream(
    client: Client, ros_env: dict[str, str], cal: Path, cli: Path
) -> None:
    """The three inputs in turn: one stream in arrival order; the typed decisions of
    array messages have the node's clock and no frame."""
    val = CORRIDOR / "deploy_S.npy"
    s_val = np.load(val)
    want = expected(cli, cal, val)
    proc = node(cal, ros_env, f"qos_depth:={DEPTH}")
    client.wait_for(proc)
    before = time.time()
    for j in range(s_val.shape[1]):
        if j % 2:
            client.scores64.publish(f64(s_val[:, j]))
        else:
            client.scores_msg.publish(scores_msg(s_val[:, j], stamped(j)))
        # Arrival order across topics is only promised one message at a time.
        client.spin_until(lambda j=j: len(client.typed) > j, f"decision {j}")
    check_decisions(client, want)
    after = time.time()
    stop(proc)
    assert_arrival_headers(client.typed[1::2], before, after)
    for j, typed in enumerate(client.typed[::2]):
        h = stamped(2 * j)
        assert (typed.header.frame_id, typed.header.stamp.sec, typed.header.stamp.nanosec) == (
            h.frame_id, h.stamp.sec, h.stamp.nanosec
        )


def test_remapped_node_logs_its_resolved_topics(ros_env: dict[str, str], cal: Path) -> None:
    """Issue 42: after ``-r __node:=other`` the start-up line names the topics the node
    uses, and the topics are there."""
    other = Client("/robot1/other")
    try:
        proc = node(cal, ros_env, remap=("__node:=other", "__ns:=/robot1", "~/scores:=/robot1/vpr/scores"))
        other.scores = other.node.create_publisher(Float32MultiArray, "/robot1/vpr/scores", QOS)
        other.wait_for(proc)
        s_val = np.load(CORRIDOR / "deploy_S.npy")
        other.scores_msg.publish(scores_msg(s_val[:, 0], stamped(0)))
        other.scores.publish(f32(s_val[:, 1]))
        other.spin_until(lambda: len(other.typed) == 2, "two decisions")
        log = stop(proc)
    finally:
        other.close()
    (line,) = [line for line in log.splitlines() if "deciding" in line]
    assert "[INFO]" in line and "[robot1.other]:" in line, line
    assert (
        "deciding /robot1/other/scores_msg, /robot1/vpr/scores, /robot1/other/scores64 into "
        "/robot1/other/decision_msg, /robot1/other/decision, /robot1/other/accept with Online(" in line
    ), line
    assert "/qtvpr/" not in line


def test_launch_file_and_parameters_of_the_docs(
    ros_env: dict[str, str], cal: Path, cli: Path, tmp_path: Path
) -> None:
    """docs/ros/qtvpr.launch.yaml's command, as ``ros2 launch`` would run it (ros2launch
    is not on PyPI: the test runs the file's one executable itself), with
    docs/ros/qtvpr.params.yaml, in a directory holding cal.npz."""
    docs = REPO / "docs" / "ros"
    (action,) = yaml.safe_load((docs / "qtvpr.launch.yaml").read_text())["launch"]
    cmd = shlex.split(action["executable"]["cmd"].replace("$(dirname)", str(docs)))
    assert cmd[:3] == ["python3", "-m", "qtvpr.ros"] and action["executable"]["output"] == "screen"
    params = yaml.safe_load((docs / "qtvpr.params.yaml").read_text())["/**"]["ros__parameters"]
    assert params["calibration"] == "cal.npz"
    (tmp_path / "cal.npz").write_bytes(cal.read_bytes())
    env = dict(ros_env, PATH=f"{Path(sys.executable).parent}{os.pathsep}{ros_env['PATH']}")
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    client = Client("/robot1/qtvpr")
    try:
        client.scores_msg = client.node.create_publisher(Scores, "/robot1/vpr/scores", QOS)
        client.wait_for(proc)
        val = CORRIDOR / "deploy_S.npy"
        s_val = np.load(val)
        headers = [stamped(j) for j in range(s_val.shape[1])]
        for j in range(s_val.shape[1]):
            client.scores_msg.publish(scores_msg(s_val[:, j], headers[j]))
        want = expected(cli, cal, val, "--window", str(params["window"]), "--gate", params["gate"])
        check_decisions(client, want, headers)
        log = stop(proc)
    finally:
        client.close()
    assert f"window={params['window']}" in log and "gate='margin'" in log and "qos_depth 300" in log


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
        # Issue 49: a misspelt name ran at the file's precision; a bool was taken as 1.
        (("calibration:={cal}", "precison:=0.5"),
         "unknown parameter precison (the node's parameters: calibration, k, precision, window, min_window, gate, "
         "sequence_window, sequence_level, sequence_speed, sequence_tolerance, sequence_drift, qos_depth)"),
        (("calibration:={cal}", "precison:=0.5", "windw:=3"), "unknown parameters precison, windw"),
        (("calibration:={cal}", "k:=true"), "parameter k must be an integer, not a bool (True)"),
        (("calibration:={cal}", "precision:=true"), "parameter precision must be a number, not a bool (True)"),
        (("calibration:={cal}", "qos_depth:=true"), "parameter qos_depth must be an integer, not a bool (True)"),
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


def test_start_up_error_of_a_remapped_node_names_it(ros_env: dict[str, str], cal: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "qtvpr.ros", "--ros-args", "-p", f"calibration:={cal}", "-p", "k:=0",
         "-r", "__node:=other", "-r", "__ns:=/robot1"],
        env=ros_env, capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 1, proc.stderr
    (line,) = [line for line in proc.stderr.splitlines() if "[ERROR]" in line]
    assert "[robot1.other]: cannot start: parameters {'k': 0}: k must be >= 1, got 0" in line, line
