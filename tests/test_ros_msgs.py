"""The ``qtvpr_msgs`` interface (``ros/qtvpr_msgs/msg/*.msg``) against the decision record.

Runs without ROS 2: the message definitions are read as text, so a field added to the
core's record (``qtvpr.OnlineDecision.RECORD``) and not to ``Decision.msg`` fails here
on every machine. ``tests/test_ros.py`` checks the generated
package against the same lists where ROS 2 is installed.
"""

from __future__ import annotations

from pathlib import Path

import qtvpr

MSG = Path(__file__).resolve().parents[1] / "ros" / "qtvpr_msgs" / "msg"

# ROS 2's type of each kind of the record's values (an index or a count is a uint64, exact).
TYPES = {"count": "uint64", "real": "float64", "flag": "bool"}


def fields(name: str) -> list[tuple[str, str]]:
    """The (type, name) of each field of ``name``.msg, comments and blank lines skipped."""
    out = []
    for line in (MSG / f"{name}.msg").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            type_, field = line.split()
            out.append((type_, field))
    return out


def test_decision_msg_is_the_record_field_for_field() -> None:
    want = [("std_msgs/Header", "header")]
    want += [(TYPES[kind], name) for name, _, kind, _ in qtvpr.OnlineDecision.RECORD]
    want += [("uint64[]", "accepted_indices")]
    assert fields("Decision") == want


def test_every_decision_field_is_documented() -> None:
    """Each field has a comment line right above it (its unit and meaning)."""
    lines = (MSG / "Decision.msg").read_text().splitlines()
    for i, line in enumerate(lines):
        if line and not line.startswith("#"):
            assert lines[i - 1].startswith("#"), line


def test_scores_msg_holds_both_float_types() -> None:
    assert fields("Scores") == [("std_msgs/Header", "header"), ("float32[]", "scores"), ("float64[]", "scores64")]


def test_the_docs_show_the_launch_and_parameter_files_the_tests_run() -> None:
    """docs/deployment.md's YAML blocks are docs/ros/qtvpr.launch.yaml and
    qtvpr.params.yaml, which tests/test_ros.py starts."""
    docs = Path(__file__).resolve().parents[1] / "docs"
    text = (docs / "deployment.md").read_text()
    blocks = [block.split("```", 1)[0] for block in text.split("```yaml\n")[1:]]
    assert blocks == [(docs / "ros" / name).read_text() for name in ("qtvpr.launch.yaml", "qtvpr.params.yaml")]
