"""Safety rules that cannot be used: refused before anything is served, naming the key's line.

Every key of a rules file has a shape (docs/safety.md, "The rules file"); a file that
breaks one, or a bound path its type does not have, is refused with ``RulesError``
naming the file and the line (D66). Rules built in Python (``TopicRule``, ``CallRule``,
``SafetyRules``) are held to the same checks, and their names are resolved as a
file's are: ``TopicRule("cmd_vel", ...)`` binds ``/cmd_vel`` (a name left unresolved
bound nothing: a remote client's command went through unclamped).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from rwt import Graph, ServerConfig
from rwt.safety import CallRule, RulesError, SafetyRules, TopicRule, parse_rules
from tests.safety.example import EXAMPLE, Robot, example_file, twist
from tests.support.cli import run_rwt
from tests.support.clients import running_server

TWIST = '[[topic]]\nname = "/cmd_vel"\ntype = "geometry_msgs/msg/Twist"\n'
"""A topic table of three lines: the next key is on line 4."""
STOP = "[topic.stop]\nlinear = { x = 0.0 }\n"

# (the file's text, the line the error names or None for none, what the error says)
BAD_FILES: dict[str, tuple[str, int | None, str]] = {
    "an unknown top-level key": ("speed = 1\n" + TWIST, 1, "unknown key 'speed'"),
    "an unknown top-level table": (TWIST + "[limits]\nspeed = 1\n", 4, "unknown key 'limits'"),
    "[topic] written for [[topic]]": (
        '[topic]\nname = "/cmd_vel"\n',
        1,
        "topic: tables ([[topic]])",
    ),
    "approval_timeout_s of zero": (
        "approval_timeout_s = 0\n" + TWIST,
        1,
        "approval_timeout_s: a number of seconds in (0, 3600]",
    ),
    "approval_timeout_s as text": (
        'approval_timeout_s = "60"\n' + TWIST,
        1,
        "approval_timeout_s: a number of seconds in (0, 3600]",
    ),
    "a file cut short": (TWIST + "max_rate_hz = ", None, "invalid value (at the end of the file)"),
    "a topic without a name": (
        '[[topic]]\ntype = "geometry_msgs/msg/Twist"\n',
        1,
        "[[topic]]: name: a topic name is needed",
    ),
    "a topic name that is not a ROS name": (
        '[[topic]]\nname = "/cmd vel"\ntype = "geometry_msgs/msg/Twist"\n',
        2,
        "[[topic]]: name '/cmd vel': invalid name '/cmd vel'",
    ),
    "a topic without a type": (
        '[[topic]]\nname = "/cmd_vel"\n',
        1,
        "/cmd_vel: type: a message type (pkg/msg/Type) is needed",
    ),
    "a rate of zero": (TWIST + "max_rate_hz = 0\n", 4, "max_rate_hz: a positive number, not 0"),
    "a rate as text": (TWIST + 'max_rate_hz = "10"\n', 4, "a positive number, not '10'"),
    "a rate of true": (TWIST + "max_rate_hz = true\n", 4, "a positive number, not True"),
    "an endless dead-man": (
        TWIST + "deadman_s = inf\n" + STOP,
        4,
        "deadman_s: a positive number, not inf",
    ),
    "a stop that is not a table": (
        TWIST + "deadman_s = 0.5\nstop = 0\n",
        5,
        "stop: a table (the message to publish)",
    ),
    "a stop without a dead-man": (TWIST + STOP, 4, "stop is the dead-man's message: add deadman_s"),
    "approval as text": (TWIST + 'approval = "yes"\n', 4, "/cmd_vel: approval: true or false"),
    "bounds that are not a table": (
        TWIST + "bounds = 5\n",
        4,
        "bounds: a table of field = [min, max]",
    ),
    "a bound of one number": (
        TWIST + '[topic.bounds]\n"linear.x" = [1]\n',
        5,
        "bounds 'linear.x': [min, max], two numbers",
    ),
    "a bound of text": (
        TWIST + '[topic.bounds]\n"linear.x" = ["slow", "fast"]\n',
        5,
        "bounds 'linear.x': [min, max], two numbers",
    ),
    "an endless bound": (
        TWIST + '[topic.bounds]\n"linear.x" = [-inf, inf]\n',
        5,
        "bounds 'linear.x': finite numbers with min <= max",
    ),
    "a path that is not a field": (
        TWIST + '[topic.bounds]\n"linear..x" = [0, 1]\n',
        5,
        "'linear..x': '' is not a field (name, name[N], name[*])",
    ),
    "an index on a field that is not an array": (
        TWIST + '[topic.bounds]\n"linear[0].x" = [0, 1]\n',
        5,
        "'linear[0].x': linear is not an array",
    ),
    "an index past a fixed array": (
        '[[topic]]\nname = "/imu"\ntype = "sensor_msgs/msg/Imu"\n'
        '[topic.bounds]\n"orientation_covariance[9]" = [0, 1]\n',
        5,
        "orientation_covariance has 9 elements",
    ),
    "a path through a number": (
        TWIST + '[topic.bounds]\n"linear.x.y" = [0, 1]\n',
        5,
        "'linear.x.y': x is a float64, not a message",
    ),
    "a bound on bytes": (
        '[[topic]]\nname = "/camera"\ntype = "sensor_msgs/msg/Image"\n'
        '[topic.bounds]\n"data[*]" = [0, 200]\n',
        5,
        "'data[*]': uint8[] is held as bytes: not bounded",
    ),
    "a stop that is not finite": (
        TWIST + "deadman_s = 0.5\n[topic.stop]\nlinear = { x = nan }\n",
        5,  # the stop's table
        "stop: linear.x is NaN, not finite",
    ),
    "a service approval that is not a bool": (
        '[[service]]\nname = "/reset"\napproval = 1\n',
        3,
        "/reset: approval: true or false",
    ),
    "a service with a topic's key": (
        '[[service]]\nname = "/reset"\ntype = "std_srvs/srv/Empty"\n',
        3,
        "/reset: unknown key 'type' (known: approval, name)",
    ),
    "an action without a name": ("[[action]]\napproval = true\n", 1, "[[action]]: name:"),
    "an action twice": (
        '[[action]]\nname = "/dock"\n[[action]]\nname = "dock"\n',
        3,
        "/dock: a second [[action]]",
    ),
}


@pytest.mark.parametrize("case", BAD_FILES, ids=str)
def test_a_bad_key_is_refused_naming_its_line(case: str) -> None:
    text, line, problem = BAD_FILES[case]
    with pytest.raises(RulesError) as refused:
        Graph(safety=parse_rules(text, "safety.toml"))
    where = f"safety.toml line {line}: " if line else "safety.toml: "
    assert refused.value.message.startswith(where), refused.value.message
    assert problem in refused.value.message


def test_more_tables_than_a_file_may_hold_are_refused() -> None:
    text = "".join(f'[[service]]\nname = "/reset_{n}"\n' for n in range(1025))
    with pytest.raises(RulesError, match=r"^safety.toml: more than 1024 tables$"):
        parse_rules(text, "safety.toml")


def test_rwt_serve_names_the_line_of_a_table_written_with_one_bracket(tmp_path: Path) -> None:
    path = example_file(tmp_path, EXAMPLE.replace("[[topic]]", "[topic]", 1).split("\n\n")[0])
    run = run_rwt("serve", "--port", "0", "--safety", str(path))
    assert run.returncode == 2
    assert run.stderr.strip() == f"rwt serve: --safety: {path} line 1: topic: tables ([[topic]])"


# ---- rules built in Python -------------------------------------------------------------


@pytest.mark.anyio
async def test_a_rule_built_in_python_binds_the_topic_in_any_spelling() -> None:
    rules = SafetyRules(
        (TopicRule("cmd_vel", "geometry_msgs/msg/Twist", {"linear.x": (-0.5, 0.5)}, "clamp"),),
        services=(CallRule("reset"),),
    )
    assert rules.topics[0].name == "/cmd_vel"
    assert rules.topics[0].bounds == {"linear.x": (-0.5, 0.5)}
    assert rules.topic("//cmd_vel/") is rules.topics[0]
    assert rules.topic("/cmd_vel_safe") is None
    assert rules.needs_approval("services", "reset")
    assert not rules.needs_approval("parameters", "/reset")  # a family that has no approvals
    robot = Robot.make(rules=rules)
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        client = await harness.connect("ws")
        await client.send({"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})
        await client.send({"op": "publish", "topic": "/cmd_vel", "msg": twist(2.0)})
        await robot.wait_for(lambda: robot.cmd_vel, "the twist")
    assert robot.twists[0]["linear"]["x"] == 0.5


def _topic(**keys: Any) -> TopicRule:
    return TopicRule(**{"name": "/cmd_vel", "type": "geometry_msgs/msg/Twist", **keys})


BAD_RULES: dict[str, tuple[Any, str]] = {
    "a dead-man without a stop": (
        lambda: _topic(deadman_s=0.5),
        "safety rules: /cmd_vel: deadman_s needs stop",
    ),
    "on_violation neither clamp nor reject": (
        lambda: _topic(on_violation="ignore"),
        "safety rules: /cmd_vel: on_violation: clamp or reject, not 'ignore'",
    ),
    "a bound upside down": (
        lambda: _topic(bounds={"linear.x": (1, -1)}),
        "safety rules: /cmd_vel: bounds 'linear.x': finite numbers with min <= max, not [1, -1]",
    ),
    "a negative rate": (
        lambda: _topic(max_rate_hz=-5),
        "safety rules: /cmd_vel: max_rate_hz: a positive number, not -5",
    ),
    "a name that is not a ROS name": (
        lambda: _topic(name="cmd-vel"),
        "safety rules: [[topic]]: name 'cmd-vel': invalid name",
    ),
    "a topic twice": (
        lambda: SafetyRules((_topic(), _topic(name="cmd_vel"))),
        "safety rules: /cmd_vel: a second [[topic]]",
    ),
    "an approval timeout of two hours": (
        lambda: SafetyRules(approval_timeout_s=7200),
        "safety rules: approval_timeout_s: a number of seconds in (0, 3600]",
    ),
    "a call approval that is not a bool": (
        lambda: CallRule("/reset", "yes"),  # type: ignore[arg-type]
        "safety rules: /reset: approval: true or false",
    ),
    "a call without a name": (
        lambda: CallRule(None),  # type: ignore[arg-type]
        "safety rules: [[service/action]]: name: a service/action name is needed",
    ),
}


@pytest.mark.parametrize("case", BAD_RULES, ids=str)
def test_a_rule_built_in_python_is_refused_as_a_files_is(case: str) -> None:
    build, problem = BAD_RULES[case]
    with pytest.raises(RulesError) as refused:
        build()
    assert refused.value.message.startswith(problem), refused.value.message


def test_a_graph_takes_one_set_of_rules() -> None:
    graph = Graph(safety=parse_rules(EXAMPLE))
    with pytest.raises(RulesError, match=r"^the graph has safety rules already$"):
        graph.use_safety(parse_rules(EXAMPLE))
