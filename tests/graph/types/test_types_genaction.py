"""ROS 1 actionlib messages made from `.action` files, checked against ROS 1's own.

genaction (ROS 1 actionlib_msgs) turns `pkg/action/X.action` into seven messages.
rwt makes them from the file; here they are compared field by field with the
messages ROS 1 ships: the rosbags ROS 1 (Noetic) store's generated actionlib and
nav_msgs action messages, and Debian's `/usr/share/nav_msgs` when installed.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.genaction import WRAPPERS
from rwt_graph.types.names import UnknownTypeError

SEVEN = ["Action", "ActionGoal", "ActionResult", "ActionFeedback", "Goal", "Result", "Feedback"]
DEBIAN_NAV = Path("/usr/share/nav_msgs")


def _fields(registry: TypeRegistry, name: str, package: str, renamed: str) -> list[object]:
    """(name, type, array kind, length) of each field, ``package/`` spelled ``renamed/``."""
    mtype = registry.message(name)
    return [
        (f.name, f.type.base.replace(f"{package}/", f"{renamed}/"), f.type.array, f.type.length)
        for f in mtype.fields
    ]


def _action_file(registry: TypeRegistry, package: str, action: str) -> str:
    """An `.action` text made of ROS 1's own Goal, Result and Feedback definitions."""
    parts = [registry.message(f"{package}/{action}{p}").definition_text() for p in SEVEN[4:]]
    return "---\n".join(parts)


@pytest.mark.parametrize(
    ("package", "action"),
    [
        ("actionlib", "TwoInts"),
        ("actionlib", "Test"),
        ("actionlib", "TestRequest"),
        ("nav_msgs", "GetMap"),
    ],
)
def test_the_seven_messages_match_the_ros1_store(tmp_path: Path, package: str, action: str) -> None:
    ros1 = TypeRegistry(Dialect.ROS1)
    folder = tmp_path / f"gen_{package}" / "action"
    folder.mkdir(parents=True)
    (folder / f"{action}.action").write_text(_action_file(ros1, package, action))
    made = TypeRegistry(Dialect.ROS1, [tmp_path])
    for part in SEVEN:
        ours = _fields(made, f"gen_{package}/{action}{part}", f"gen_{package}", package)
        theirs = _fields(ros1, f"{package}/{action}{part}", package, package)
        assert ours == theirs, part
        assert ours or part not in WRAPPERS  # (a Goal may be empty: GetMap's is)


@pytest.mark.skipif(
    not (DEBIAN_NAV / "action" / "GetMap.action").is_file(),
    reason="Debian's ROS 1 nav_msgs definitions are not installed (apt-get install ros-nav-msgs)",
)
def test_the_seven_messages_match_what_debian_ships(tmp_path: Path) -> None:
    """Debian ships genaction's output for nav_msgs/GetMap next to the `.action` file."""
    shipped = tmp_path / "shipped"
    shutil.copytree(DEBIAN_NAV / "msg", shipped / "nav_msgs" / "msg")
    debian = TypeRegistry(Dialect.ROS1, [shipped])
    made_dir = tmp_path / "made" / "mine" / "action"
    made_dir.mkdir(parents=True)
    shutil.copy(DEBIAN_NAV / "action" / "GetMap.action", made_dir)
    made = TypeRegistry(Dialect.ROS1, [tmp_path / "made"])
    for part in SEVEN:
        ours = _fields(made, f"mine/GetMap{part}", "mine", "nav_msgs")
        assert ours == _fields(debian, f"nav_msgs/GetMap{part}", "nav_msgs", "nav_msgs"), part


def test_actionlib_tutorials_ship_in_the_ros1_set() -> None:
    ros1 = TypeRegistry(Dialect.ROS1)
    goal = ros1.message("actionlib_tutorials/FibonacciActionGoal")
    assert [f.name for f in goal.fields] == ["header", "goal_id", "goal"]
    assert [f.type.base for f in goal.fields] == [
        "std_msgs/Header",
        "actionlib_msgs/GoalID",
        "actionlib_tutorials/FibonacciGoal",
    ]
    averaging = ros1.message("actionlib_tutorials/AveragingFeedback")
    assert [f.name for f in averaging.fields] == ["sample", "data", "mean", "std_dev"]
    whole = ros1.message("actionlib_tutorials/FibonacciAction")
    assert [f.name for f in whole.fields] == ["action_goal", "action_result", "action_feedback"]
    # a goal message converts like any other (defaults for the header and the id)
    value = goal.default(now=0.0)
    assert value["goal"] == {"order": 0}
    goal_id = value["goal_id"]
    assert isinstance(goal_id, dict)
    assert set(goal_id) == {"stamp", "id"}


def test_the_wrappers_are_ros1_only() -> None:
    """ROS 2 actions have no such messages (they travel as the action's own types)."""
    with pytest.raises(UnknownTypeError):
        TypeRegistry(Dialect.ROS2).message("example_interfaces/FibonacciActionGoal")
    assert set(WRAPPERS) == set(SEVEN[:4])


def test_a_wrapper_without_its_action_file_is_unknown() -> None:
    with pytest.raises(UnknownTypeError):
        TypeRegistry(Dialect.ROS1).message("actionlib_tutorials/NoSuchActionGoal")
