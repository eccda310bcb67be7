"""A ROS 2 node that decides every deployment query: ``python -m qtvpr.ros``.

The node (named ``qtvpr``) is :class:`qtvpr.Online` on a ROS 2 graph, and nothing else:
it converts each message of scores into a column, pushes it, and converts the decision
back into messages. Its decisions are therefore those of ``qtvpr-cli stream`` for the
same columns, bit for bit, float32 or float64.

Parameters (``--ros-args -p name:=value``):

- ``calibration`` (string, required): the calibration file (``qtvpr-cli calibrate``,
  :meth:`qtvpr.Calibration.save`).
- ``k``, ``precision``, ``window``, ``min_window``, ``gate`` and the sequence gate's
  ``sequence_window``, ``sequence_level``, ``sequence_speed``, ``sequence_tolerance``,
  ``sequence_drift``: as :class:`qtvpr.Online` (docs/semantics.md §11-§13, §15); left
  unset, each takes the file's value (the core's resolution, as ``stream``). Invalid
  values are refused at start-up. The sequence length ``L`` is the calibration file's
  (``qtvpr-cli calibrate --sequence L``): each query is then decided on its causal
  sequence-matched column, from the raw scores the node is sent.
- ``qos_depth`` (integer, default :data:`QOS_DEPTH`): the keep-last depth of every topic
  (all reliable), the backlog of messages the node holds while it decides.

Any other parameter (a misspelt ``precison``, say) is refused at start-up, as is a bool
for a number (``-p k:=true``, which Python would count as 1); ``use_sim_time`` and the
other parameters every ROS 2 node declares are accepted.

Topics (relative to the node: ``/qtvpr/...`` by default; remap them as any ROS topic):

- subscribes ``~/scores_msg`` (``qtvpr_msgs/Scores``): a header (the query's stamp and
  frame) and one query's |DB| scores in the matcher's own type: ``scores`` (float32) or
  ``scores64`` (float64), exactly one of them non-empty (float64 scores rounded to
  float32 are other scores). Also ``~/scores`` (``std_msgs/Float32MultiArray``) and
  ``~/scores64`` (``std_msgs/Float64MultiArray``), the scores in ``data`` and no header.
  All three feed the one stream, in arrival order.
- publishes, for every decision, ``~/decision_msg`` (``qtvpr_msgs/Decision``): the
  record field for field, named as :data:`DECISION_FIELDS` (then ``accepted_indices``),
  its header the query's (the stamp and frame_id of its ``Scores``; after an array
  message, which has none, the node's clock at its arrival and an empty frame_id);
  ``~/decision`` (``std_msgs/Float64MultiArray``): the record's ``data`` in the order of
  :data:`DECISION_FIELDS`; and ``~/accept`` (``std_msgs/Bool``): its ``accept``.

A decision as float64: ``query``, ``best`` and ``accepted`` are integers below 2**53,
exact as float64; ``accept`` is 1.0 or 0.0; ``margin`` and ``gate`` are NaN when the
stream has no margin gate, ``consistency`` and ``consistency_level`` when it has no
sequence gate (in both messages). The layout has one dimension, labelled
with the field names joined by commas (``layout.dim[0].label``), of size
``len(DECISION_FIELDS)``.

A message the core refuses (another length than |DB|, a NaN or infinite score, an
empty array; a ``Scores`` with both arrays filled or both empty) is logged as one error
line naming the message (its stamp, if it has one), the queries decided so far and the
problem; it gets no decision, the window is unchanged, and the node goes on. A
missing, unreadable or corrupt calibration file, or invalid parameters, are logged and
the process exits with status 1 at start-up.

Needs ROS 2 Jazzy's Python client and messages, from PyPI (wheels for CPython 3.11), and
the interface package of the clone's ``ros/qtvpr_msgs``, which pip builds with ROS 2's
generators: ``pip install ".[ros]" ./ros/qtvpr_msgs`` from a clone (docs/deployment.md).
"""

from __future__ import annotations

import array
import math
import sys
from typing import Any

import numpy as np

from qtvpr._native import Calibration, Online, OnlineDecision

_NEEDS = (
    "qtvpr.ros needs ROS 2 Jazzy's rclpy and std_msgs and the qtvpr_msgs interface: from a clone, "
    'pip install ".[ros]" ./ros/qtvpr_msgs (wheels for CPython 3.11 only)'
)

try:
    import rclpy
    from qtvpr_msgs.msg import Decision, Scores
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Bool, Float32MultiArray, Float64MultiArray, Header, MultiArrayDimension
except ImportError as err:  # pragma: no cover - exercised only without the extra
    if __name__ == "__main__":
        print(f"error: {_NEEDS} ({err})", file=sys.stderr)
        sys.exit(2)
    raise ImportError(_NEEDS) from err

__all__ = ["DECISION_FIELDS", "DECISION_MSG_FIELDS", "NODE_NAME", "ONLINE_PARAMETERS", "QOS_DEPTH", "QtvprNode", "main"]

#: The fields of a ``~/decision`` message's ``data``, in order: the core's record
#: (:attr:`qtvpr.OnlineDecision.FIELDS`), then its margin-gate fields
#: (:attr:`qtvpr.OnlineDecision.GATE_FIELDS`) and its sequence-gate fields
#: (:attr:`qtvpr.OnlineDecision.SEQUENCE_FIELDS`), NaN without their gate.
DECISION_FIELDS: tuple[str, ...] = OnlineDecision.FIELDS + OnlineDecision.GATE_FIELDS + OnlineDecision.SEQUENCE_FIELDS

#: The fields of a ``qtvpr_msgs/Decision`` (``~/decision_msg``), in order: its header,
#: :data:`DECISION_FIELDS`, and the record's ``accepted_indices``.
DECISION_MSG_FIELDS: tuple[str, ...] = ("header", *DECISION_FIELDS, "accepted_indices")

#: The node's name.
NODE_NAME = "qtvpr"

#: The ROS parameters passed to :class:`qtvpr.Online` when set (unset: the file's).
ONLINE_PARAMETERS: tuple[str, ...] = (
    "k",
    "precision",
    "window",
    "min_window",
    "gate",
    "sequence_window",
    "sequence_level",
    "sequence_speed",
    "sequence_tolerance",
    "sequence_drift",
)

#: The default keep-last depth of the node's topics (parameter ``qos_depth``): at 30
#: queries a second, about three seconds of backlog.
QOS_DEPTH = 100

#: The numeric parameters and what each must be: a bool is none of them.
_NUMBERS = {"k": "an integer", "precision": "a number", "window": "an integer", "min_window": "an integer",
            "sequence_window": "an integer", "sequence_level": "a number", "sequence_speed": "a number",
            "sequence_tolerance": "a number", "sequence_drift": "a number", "qos_depth": "an integer"}


class StartupError(Exception):
    """A calibration or parameter the node cannot start with; its message says which."""

    #: The logger of the node that could not start (its resolved name).
    logger_name: str = NODE_NAME


def decision_array(decision: OnlineDecision) -> list[float]:
    """The values of ``decision`` in the order of :data:`DECISION_FIELDS`, as float64
    (``None``, a field of a gate the stream has not, is NaN)."""
    values = (getattr(decision, name) for name in DECISION_FIELDS)
    return [math.nan if v is None else float(v) for v in values]


def decision_msg(decision: OnlineDecision, header: Header) -> Decision:
    """``decision`` as a ``qtvpr_msgs/Decision`` with ``header`` (``None``, a field of a
    gate the stream has not, is NaN)."""
    msg = Decision(header=header)
    for name in DECISION_FIELDS:
        value = getattr(decision, name)
        setattr(msg, name, math.nan if value is None else value)
    # Indices below |DB|: the same bytes as uint64.
    msg.accepted_indices = array.array("Q", decision.accepted_indices.tobytes())
    return msg


class QtvprNode(Node):  # type: ignore[misc]
    """The ``qtvpr`` node: reads its parameters, loads the calibration and builds the
    :class:`qtvpr.Online` state. Raises :class:`StartupError` when it cannot."""

    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        try:
            self._start()
        except StartupError as err:
            err.logger_name = self.get_logger().name  # the node's own, after -r __node:=...
            raise

    def _start(self) -> None:
        """Parameters, calibration, ``Online``, topics; :class:`StartupError` if it cannot."""
        untyped = ParameterDescriptor(dynamic_typing=True)
        # Declared without a value: unset means "the file's", decided by the core.
        self.declare_parameter("calibration", None, untyped)
        for name in ONLINE_PARAMETERS:
            self.declare_parameter(name, None, untyped)
        self.declare_parameter("qos_depth", QOS_DEPTH, untyped)
        # The parameters given (the command line's, a parameter file's) that no one
        # declared: rclpy keeps them as overrides of the node (an attribute Node sets
        # for its subclasses) and would silently ignore them.
        unknown = sorted(name for name in self._parameter_overrides if not self.has_parameter(name))
        if unknown:
            known = ", ".join(("calibration", *ONLINE_PARAMETERS, "qos_depth"))
            plural = "s" if len(unknown) > 1 else ""
            raise StartupError(f"unknown parameter{plural} {', '.join(unknown)} (the node's parameters: {known})")
        for name, kind in _NUMBERS.items():
            value = self.get_parameter(name).value
            if isinstance(value, bool):
                raise StartupError(f"parameter {name} must be {kind}, not a bool ({value})")

        path = self.get_parameter("calibration").value
        if not isinstance(path, str) or not path:
            raise StartupError("parameter calibration (a calibration file, .npz) is required: -p calibration:=cal.npz")
        try:
            calibration = Calibration.load(path)
        except (OSError, ValueError) as err:
            raise StartupError(f"calibration {path}: {err}") from err
        given = {name: self.get_parameter(name).value for name in ONLINE_PARAMETERS}
        given = {name: value for name, value in given.items() if value is not None}
        try:
            self.online = Online(calibration, **given)
        except (TypeError, ValueError) as err:
            raise StartupError(f"parameters {given}: {err}") from err
        depth = self.get_parameter("qos_depth").value
        if not isinstance(depth, int) or depth < 1:
            raise StartupError(f"parameter qos_depth must be an integer of at least 1, not {depth!r}")

        qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=depth)
        self.db_size = calibration.db_size
        self.messages = 0
        self._decision_msg = self.create_publisher(Decision, "~/decision_msg", qos)
        self._decision = self.create_publisher(Float64MultiArray, "~/decision", qos)
        self._accept = self.create_publisher(Bool, "~/accept", qos)
        self._layout = [
            MultiArrayDimension(label=",".join(DECISION_FIELDS), size=len(DECISION_FIELDS), stride=len(DECISION_FIELDS))
        ]
        subscriptions = [
            self.create_subscription(Scores, "~/scores_msg", self._on_scores_msg, qos),
            self.create_subscription(Float32MultiArray, "~/scores", self._on_array(np.float32), qos),
            self.create_subscription(Float64MultiArray, "~/scores64", self._on_array(np.float64), qos),
        ]
        # The resolved names: namespace, node name and remappings applied.
        inputs = ", ".join(sub.topic_name for sub in subscriptions)
        outputs = ", ".join(pub.topic_name for pub in (self._decision_msg, self._decision, self._accept))
        self.get_logger().info(
            f"deciding {inputs} into {outputs} with {self.online!r} "
            f"(|DB| = {self.db_size}, calibration {path}, qos_depth {depth})"
        )

    def _on_array(self, dtype: type[np.floating[Any]]) -> Any:
        """The callback of an array topic whose ``data`` holds ``dtype`` values."""

        def callback(msg: Any) -> None:
            self.messages += 1
            # No header: the decision's is the arrival time, no frame.
            header = Header(stamp=self.get_clock().now().to_msg())
            # msg.data is an array.array of the message's own type: read in place.
            self._decide(np.frombuffer(msg.data, dtype=dtype), header, "")

        return callback

    def _on_scores_msg(self, msg: Any) -> None:
        """The callback of ``~/scores_msg``: the one non-empty array, in its own type."""
        self.messages += 1
        n32, n64 = len(msg.scores), len(msg.scores64)
        stamp = f", stamp {msg.header.stamp.sec}.{msg.header.stamp.nanosec:09d}"
        if (n32 == 0) == (n64 == 0):
            self.get_logger().error(
                f"scores message {self.messages} (qtvpr_msgs/Scores{stamp}; {self.online.pushed} queries decided): "
                f"exactly one of scores (float32) and scores64 (float64) must hold the column, "
                f"not {n32} and {n64} scores; not decided, the window is unchanged"
            )
            return
        column = np.frombuffer(msg.scores, dtype=np.float32) if n32 else np.frombuffer(msg.scores64, dtype=np.float64)
        self._decide(column, msg.header, stamp)

    def _decide(self, column: np.ndarray, header: Header, stamp: str) -> None:
        """Push ``column``; publish its decision on every output topic, or log why not."""
        try:
            decision = self.online.push(column)
        except (TypeError, ValueError) as err:
            self.get_logger().error(
                f"scores message {self.messages} ({column.dtype.name}, {column.size} scores{stamp}; "
                f"{self.online.pushed} queries decided): {err}; not decided, the window is unchanged"
            )
            return
        self._decision_msg.publish(decision_msg(decision, header))
        out = Float64MultiArray()
        out.layout.dim = self._layout
        out.data = array.array("d", decision_array(decision))
        self._decision.publish(out)
        self._accept.publish(Bool(data=decision.accept))


def main(args: list[str] | None = None) -> int:
    """Run the node until it is shut down (Ctrl-C, SIGTERM or the ROS context); the exit
    status: 0, or 1 when it cannot start."""
    rclpy.init(args=args)
    try:
        try:
            node = QtvprNode()
        except StartupError as err:
            rclpy.logging.get_logger(err.logger_name).error(f"cannot start: {err}")
            return 1
        try:
            rclpy.spin(node)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            node.destroy_node()
        return 0
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main(sys.argv))
