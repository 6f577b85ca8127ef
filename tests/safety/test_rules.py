"""The rules file: read with each key's line, checked against the types, refused at start.

``rwt serve --safety FILE`` refuses, before it serves, a file that does not parse, names
a field its type lacks, bounds a field that is not a number, or has a key or a value it
does not know: exit 2 and one line naming the file's line (docs/safety.md, D66).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from rwt import Graph
from rwt_graph.safety.envelope import STATUS_TOPIC
from rwt_graph.safety.rules import RulesError, load_rules, parse_rules
from tests.safety.example import EXAMPLE, docs_page, example_file
from tests.support.cli import run_rwt
from tests.support.realclients import REPO


def test_the_example_reads_as_written() -> None:
    rules = parse_rules(EXAMPLE, "safety.toml")
    cmd_vel, joint = rules.topics
    assert (cmd_vel.name, cmd_vel.type, cmd_vel.on_violation) == (
        "/cmd_vel",
        "geometry_msgs/msg/Twist",
        "clamp",
    )
    assert dict(cmd_vel.bounds) == {"linear.x": (-0.5, 0.5), "angular.z": (-1.0, 1.0)}
    assert (cmd_vel.deadman_s, cmd_vel.approval, cmd_vel.max_rate_hz) == (0.5, True, None)
    assert cmd_vel.stop == {
        "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
    }
    assert (joint.name, joint.on_violation, dict(joint.bounds)) == (
        "/arm/joint_cmd",
        "reject",
        {"data": (0.0, 3.14)},
    )
    assert rules.needs_approval("topics", "cmd_vel")
    assert not rules.needs_approval("topics", "/arm/joint_cmd")


def test_a_graph_holds_the_bounded_topics_with_their_types() -> None:
    graph = Graph(safety=parse_rules(EXAMPLE))
    topics = dict(graph.topic_names_and_types())
    assert topics["/cmd_vel"] == "geometry_msgs/msg/Twist"
    assert topics["/arm/joint_cmd"] == "std_msgs/msg/Float64"
    assert topics[STATUS_TOPIC] == "std_msgs/msg/String"


def _replaced(old: str, new: str) -> str:
    assert old in EXAMPLE
    return EXAMPLE.replace(old, new, 1)


# (the file's text, its line the error names, what the error says)
BAD_FILES = {
    "not TOML": ('[[topic]\nname = "/cmd_vel"\n', 1, "expected ']]'"),
    "a value that is not TOML": (_replaced("deadman_s = 0.5", "deadman_s = 0.5s"), 5, "column"),
    "a field the type lacks": (
        _replaced('"angular.z"', '"angular.w"'),
        9,
        "geometry_msgs/msg/Vector3 has no field 'w'",
    ),
    "a bound on a field that is not a number": (
        EXAMPLE + '\n[[topic]]\nname = "/say"\ntype = "std_msgs/msg/String"\n'
        '[topic.bounds]\n"data" = [0, 1]\n',
        25,
        "data is a string, not a number field",
    ),
    "a bound on a message": (_replaced('"linear.x"', '"linear"'), 8, "not a number field"),
    "an unknown key": (_replaced("approval = true", "aproval = true"), 6, "unknown key 'aproval'"),
    "an unknown type": (
        _replaced("geometry_msgs/msg/Twist", "geometry_msgs/msg/Twists"),
        3,
        "unknown message type",
    ),
    "a bound upside down": (_replaced("[0.0, 3.14]", "[3.14, 0.0]"), 19, "min <= max"),
    "a dead-man without a stop": (
        _replaced("deadman_s = 0.5", "deadman_s = 0.5").split("[topic.stop]")[0]
        + EXAMPLE.split("angular = { x = 0.0, y = 0.0, z = 0.0 }\n", 1)[1],
        5,
        "deadman_s needs stop",
    ),
    "a stop outside its own bounds": (
        _replaced("linear = { x = 0.0", "linear = { x = 1.0"),
        10,
        "stop: linear.x 1.0 is outside [-0.5, 0.5]",
    ),
    "a stop that does not fit the type": (
        _replaced("linear = { x = 0.0", "linear = { x = 'fast'"),
        10,
        "stop:",
    ),
    "on_violation neither clamp nor reject": (
        _replaced('on_violation = "reject"', 'on_violation = "ignore"'),
        17,
        "clamp or reject",
    ),
    "a topic twice": (EXAMPLE + "\n" + EXAMPLE.split("\n\n")[1], 21, "a second [[topic]]"),
}


@pytest.mark.parametrize("case", BAD_FILES, ids=str)
def test_a_bad_file_is_refused_naming_its_line(case: str) -> None:
    text, line, problem = BAD_FILES[case]
    with pytest.raises(RulesError) as refused:
        Graph(safety=parse_rules(text, "safety.toml"))
    assert refused.value.message.startswith(f"safety.toml line {line}: ")
    assert problem in refused.value.message


@pytest.mark.parametrize(
    "case", ["not TOML", "a field the type lacks", "a bound on a field that is not a number"]
)
def test_rwt_serve_refuses_a_bad_file_at_start(tmp_path: Path, case: str) -> None:
    text, line, problem = BAD_FILES[case]
    path = example_file(tmp_path, text)
    run = run_rwt("serve", "--port", "0", "--safety", str(path))
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1, run.stderr
    assert lines[0].startswith(f"rwt serve: --safety: {path} line {line}: ")
    assert problem in lines[0]
    assert "listening" not in run.stdout


def test_rwt_serve_refuses_a_missing_file(tmp_path: Path) -> None:
    run = run_rwt("serve", "--port", "0", "--safety", str(tmp_path / "none.toml"))
    assert run.returncode == 2
    assert "--safety" in run.stderr
    assert "no such file" in run.stderr


def test_load_rules_names_the_file(tmp_path: Path) -> None:
    rules = load_rules(example_file(tmp_path))
    assert rules.source == str(tmp_path / "safety.toml")
    with pytest.raises(RulesError, match="cannot read"):
        load_rules(tmp_path)


def test_the_rules_do_not_fit_a_topic_that_has_another_type() -> None:
    graph = Graph()
    graph.create_publisher("/cmd_vel", "std_msgs/msg/String")
    with pytest.raises(RulesError, match="established with type std_msgs/msg/String"):
        graph.use_safety(parse_rules(EXAMPLE, "safety.toml"))


def test_array_elements_and_every_element_are_bounded() -> None:
    text = (
        '[[topic]]\nname = "/joints"\ntype = "sensor_msgs/msg/JointState"\n'
        'on_violation = "clamp"\n[topic.bounds]\n"position[0]" = [0, 1]\n"velocity[*]" = [-2, 2]\n'
    )
    graph = Graph(safety=parse_rules(text, "joints.toml"))
    heard: list[dict[str, object]] = []
    graph.create_subscription("/joints", heard.append)
    graph.port.publish(
        "ws:10.0.0.1:4000#1",
        "/joints",
        {"position": [5.0, 7.0], "velocity": [3.0, -1.0, -9.0]},
    )
    assert list(heard[0]["position"]) == [1.0, 7.0]  # type: ignore[call-overload]
    assert list(heard[0]["velocity"]) == [2.0, -1.0, -2.0]  # type: ignore[call-overload]
    with pytest.raises(RulesError, match=r"position is an array: name an element"):
        Graph(safety=parse_rules(text.replace('"position[0]"', '"position"'), "joints.toml"))


def test_the_shipped_example_and_the_docs_show_the_file_the_tests_use() -> None:
    assert (REPO / "examples" / "safety.toml").read_text("utf-8") == EXAMPLE
    assert f"```text\n{EXAMPLE}```" in docs_page()


def test_rwt_mcp_refuses_a_file_that_does_not_parse(tmp_path: Path) -> None:
    path = example_file(tmp_path, "[[topic]\n")
    run = run_rwt("mcp", "ws://127.0.0.1:9", "--safety", str(path))
    assert run.returncode == 2
    assert "--safety" in run.stderr
    assert f"{path} line 1: expected ']]'" in run.stderr


def test_a_bound_in_an_inline_table_names_its_line() -> None:
    text = (
        '[[topic]]\nname = "/cmd_vel"\ntype = "geometry_msgs/msg/Twist"\n'
        'bounds = { "linear.q" = [0, 1] }\n'
    )
    with pytest.raises(RulesError, match=r"^safety.toml line 4: /cmd_vel: .* has no field 'q'"):
        Graph(safety=parse_rules(text, "safety.toml"))
