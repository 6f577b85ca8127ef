"""ROS 1 types are written in their Noetic ``.msg`` file's order, as ROS 2 types in Kilted's.

rosbags' ROS 1 (Noetic) store keeps a message's constants apart from its fields; the
``ros1_types`` of ``rwt_graph/types/declaration_order.json`` put them back where the
file declares them. The reference is ``noetic_reference.json``: the member lines (no
comments) of every message of the Noetic packages the store holds, and the Goal, Result
and Feedback of their actions as genaction makes them. Both are written from the
packages' sources (common_msgs, std_msgs, ros_comm_msgs, actionlib, bond_core,
dynamic_reconfigure, ros_comm at the commits ``source`` names), never read at run time::

    python -m tests.graph.types.test_ros1_declaration_order SOURCE_DIR...
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest
from tests.graph.types.test_declaration_order import declared_names, write_section

from rwt_graph.types import Dialect, TypeRegistry, sources

REFERENCE = Path(__file__).with_name("noetic_reference.json")
SOURCE = (
    "ROS 1 Noetic sources: ros/common_msgs noetic-devel 20a833b56f, ros/std_msgs"
    " kinetic-devel f3554d4182, ros/ros_comm_msgs kinetic-devel f51a042996,"
    " ros/actionlib noetic-devel 3558eb3c6c, ros/bond_core kinetic-devel 5a79fecb3e,"
    " ros/dynamic_reconfigure noetic-devel 2654f228ad, ros/ros_comm noetic-devel 845f74602c"
)
ACTION_PARTS = ("Goal", "Result", "Feedback")


def member_lines(text: str) -> str:
    """The constant and field lines of ROS 1 ``.msg`` text, comments dropped."""
    lines = []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        # a string constant's value is the rest of the line, '#' included (ROS 1 msg spec)
        if not re.match(r"string\s+\w+\s*=", stripped):
            stripped = stripped.split("#", 1)[0].strip()
        lines.append(stripped)
    return "\n".join(lines)


def read_sources(roots: list[Path]) -> dict[str, str]:
    """``{"pkg/msg/Type": member lines}`` of every package found under ``roots``."""
    found: dict[str, str] = {}
    for root in roots:
        for manifest in sorted(root.rglob("package.xml")):
            folder = manifest.parent
            if "test" in folder.relative_to(root).parts:
                continue
            name = re.search(r"<name>\s*([\w-]+)\s*</name>", manifest.read_text()).group(1)  # type: ignore[union-attr]
            if name.startswith(("test_", "perf")):
                continue
            for path in sorted(folder.glob("msg/*.msg")):
                found[f"{name}/msg/{path.stem}"] = member_lines(path.read_text())
            for path in sorted(folder.glob("action/*.action")):
                parts = re.split(r"^---\s*$", path.read_text(), flags=re.MULTILINE)
                for part, text in zip(ACTION_PARTS, parts, strict=True):
                    found[f"{name}/msg/{path.stem}{part}"] = member_lines(text)
                found.update(genaction_wrappers(name, path.stem))
    return found


def genaction_wrappers(package: str, action: str) -> dict[str, str]:
    """The messages ROS 1's genaction writes around an action's parts (its template)."""
    key = f"{package}/msg/{action}"
    return {
        f"{key}Action": (
            f"{action}ActionGoal action_goal\n{action}ActionResult action_result\n"
            f"{action}ActionFeedback action_feedback"
        ),
        f"{key}ActionGoal": f"Header header\nactionlib_msgs/GoalID goal_id\n{action}Goal goal",
        f"{key}ActionResult": (
            f"Header header\nactionlib_msgs/GoalStatus status\n{action}Result result"
        ),
        f"{key}ActionFeedback": (
            f"Header header\nactionlib_msgs/GoalStatus status\n{action}Feedback feedback"
        ),
    }


def reference() -> dict[str, str]:
    return json.loads(REFERENCE.read_text(encoding="utf-8"))["types"]  # type: ignore[no-any-return]


def store_order(key: str) -> list[str]:
    """The ROS 1 store's members as rosbags keeps them: constants, then fields."""
    consts, fields = sources.store_for(Dialect.ROS1)[key]
    names = [name for name, _, _ in consts] + [name for name, _ in fields]
    return [name for name in names if name != sources.IDL_PLACEHOLDER]


def file_orders(texts: dict[str, str]) -> dict[str, list[str]]:
    """Each ROS 1 store message whose file does not declare its constants first."""
    orders = {}
    for key in sources.store_for(Dialect.ROS1):
        if key not in texts:
            continue
        written = declared_names(texts[key])
        if written != store_order(key) and sorted(written) == sorted(store_order(key)):
            orders[key] = written
    return orders


@pytest.fixture(scope="module")
def registry() -> TypeRegistry:
    return TypeRegistry(Dialect.ROS1)


def shipped() -> list[str]:
    """The reference's types that a ROS 1 graph serves."""
    known = set(TypeRegistry(Dialect.ROS1).message_names())  # spelled pkg/Type
    return sorted(key for key in reference() if key.replace("/msg/", "/") in known)


def test_the_reference_covers_the_ros1_store() -> None:
    # every message of the store has its Noetic file in the reference
    missing = set(sources.store_for(Dialect.ROS1)) - set(reference())
    assert missing <= {"builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"}


@pytest.mark.parametrize("key", shipped())
def test_each_shipped_ros1_type_keeps_its_files_order(registry: TypeRegistry, key: str) -> None:
    text = registry.message(key).definition_text()
    assert declared_names(text) == declared_names(reference()[key])


def test_the_packaged_ros1_order_is_what_the_reference_gives() -> None:
    packaged = sources.declaration_orders(Dialect.ROS1)
    assert {key: list(names) for key, names in packaged.items()} == file_orders(reference())
    assert "shape_msgs/msg/SolidPrimitive" in packaged  # rendered from the store


if __name__ == "__main__":
    texts = read_sources([Path(arg) for arg in sys.argv[1:]])
    lines = [f"{json.dumps(key)}: {json.dumps(text)}" for key, text in sorted(texts.items())]
    body = ",\n".join(lines)
    REFERENCE.write_text(
        f'{{"source": {json.dumps(SOURCE)}, "types": {{\n{body}\n}}}}\n', encoding="utf-8"
    )
    write_section("ros1_types", SOURCE, file_orders(texts))
