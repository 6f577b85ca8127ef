"""Types from the rosbags store are advertised in their ``.msg`` file's order.

rosbags keeps a message's constants apart from its fields, so a definition
rendered from the store would list every constant first. Lichtblick compares
each advertised ROS 2 schema with its own copy, order included, and alerts when
they differ. ``rwt_graph/types/declaration_order.json`` records the order of the
files of ROS 2 Kilted that do not declare all constants first; it is written
from installed ``share/<pkg>/msg`` folders (the ``ros-kilted-*`` wheels put them
under the interpreter's prefix), never read from them at run time::

    python -m tests.graph.types.test_declaration_order [MORE_SHARE_DIRS...]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from rwt_foxglove.schemas import schema_of
from rwt_graph.types import Dialect, TypeRegistry, sources
from rwt_graph.types.spec import Constant, FieldSpec, FieldType

INSTALLED_SHARE = Path(sys.prefix) / "share"

#: Member names in the order of each upstream file (ROS 2 common_interfaces, Kilted).
EXPECTED = {
    "actionlib_msgs/msg/GoalStatus": [
        "goal_id",
        "status",
        "PENDING",
        "ACTIVE",
        "PREEMPTED",
        "SUCCEEDED",
        "ABORTED",
        "REJECTED",
        "PREEMPTING",
        "RECALLING",
        "RECALLED",
        "LOST",
        "text",
    ],
    "sensor_msgs/msg/NavSatFix": [
        "header",
        "status",
        "latitude",
        "longitude",
        "altitude",
        "position_covariance",
        "COVARIANCE_TYPE_UNKNOWN",
        "COVARIANCE_TYPE_APPROXIMATED",
        "COVARIANCE_TYPE_DIAGONAL_KNOWN",
        "COVARIANCE_TYPE_KNOWN",
        "position_covariance_type",
    ],
    "shape_msgs/msg/SolidPrimitive": [
        "BOX",
        "SPHERE",
        "CYLINDER",
        "CONE",
        "PRISM",
        "type",
        "dimensions",
        "BOX_X",
        "BOX_Y",
        "BOX_Z",
        "SPHERE_RADIUS",
        "CYLINDER_HEIGHT",
        "CYLINDER_RADIUS",
        "CONE_HEIGHT",
        "CONE_RADIUS",
        "PRISM_HEIGHT",
        "polygon",
    ],
    "visualization_msgs/msg/InteractiveMarkerControl": [
        "name",
        "orientation",
        "INHERIT",
        "FIXED",
        "VIEW_FACING",
        "orientation_mode",
        "NONE",
        "MENU",
        "BUTTON",
        "MOVE_AXIS",
        "MOVE_PLANE",
        "ROTATE_AXIS",
        "MOVE_ROTATE",
        "MOVE_3D",
        "ROTATE_3D",
        "MOVE_ROTATE_3D",
        "interaction_mode",
        "always_visible",
        "markers",
        "independent_marker_orientation",
        "description",
    ],
    "visualization_msgs/msg/InteractiveMarkerFeedback": [
        "header",
        "client_id",
        "marker_name",
        "control_name",
        "KEEP_ALIVE",
        "POSE_UPDATE",
        "MENU_SELECT",
        "BUTTON_CLICK",
        "MOUSE_DOWN",
        "MOUSE_UP",
        "event_type",
        "pose",
        "menu_entry_id",
        "mouse_point",
        "mouse_point_valid",
    ],
    "visualization_msgs/msg/InteractiveMarkerUpdate": [
        "server_id",
        "seq_num",
        "KEEP_ALIVE",
        "UPDATE",
        "type",
        "markers",
        "poses",
        "erases",
    ],
    "visualization_msgs/msg/MenuEntry": [
        "id",
        "parent_id",
        "title",
        "command",
        "FEEDBACK",
        "ROSRUN",
        "ROSLAUNCH",
        "command_type",
    ],
}


def declared_names(text: str) -> list[str]:
    """The constant and field names of ``.msg`` text, in the order written."""
    names = []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        names.append(stripped.split(None, 2)[1].split("=", 1)[0])
    return names


def installed_file(key: str, share_dirs: list[Path]) -> Path | None:
    """The ``.msg`` file of ``pkg/msg/Type`` in the first share folder that has it."""
    package, _, name = key.split("/")
    for share in share_dirs:
        path = share / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path
    return None


def store_order(key: str) -> list[str]:
    """The store's members as rosbags keeps them: constants, then fields."""
    consts, fields = sources.store_for(Dialect.ROS2)[key]
    names = [name for name, _, _ in consts] + [name for name, _ in fields]
    return [name for name in names if name != sources.IDL_PLACEHOLDER]


def typed_keys() -> list[str]:
    """The ROS 2 store's messages that have constants."""
    return [key for key, (consts, _) in sources.store_for(Dialect.ROS2).items() if consts]


def file_orders(share_dirs: list[Path]) -> dict[str, list[str]]:
    """Each store message with constants whose file is found and does not put them first."""
    orders = {}
    for key in typed_keys():
        path = installed_file(key, share_dirs)
        if path is None:
            continue
        written = declared_names(path.read_text(encoding="utf-8"))
        if written != store_order(key) and sorted(written) == sorted(store_order(key)):
            orders[key] = written
    return orders


def render_json(sections: dict[str, tuple[str, dict[str, list[str]]]]) -> str:
    """The text of the order file: ``{section: (source, orders)}``, one type a line."""
    parts = []
    for section, (source, orders) in sections.items():
        lines = [f"{json.dumps(key)}: {json.dumps(names)}" for key, names in sorted(orders.items())]
        source_key = "source" if section == "types" else section.replace("types", "source")
        parts.append(f"{json.dumps(source_key)}: {json.dumps(source)}")
        parts.append(f"{json.dumps(section)}: {{\n" + ",\n".join(lines) + "\n}")
    return "{" + ",\n".join(parts) + "}\n"


def write_section(section: str, source: str, orders: dict[str, list[str]]) -> None:
    """Replace one store's orders in the order file, keeping the other's."""
    data = json.loads(sources.DECLARATION_ORDER.read_text(encoding="utf-8"))
    sections = {
        name: (data["source" if name == "types" else name.replace("types", "source")], value)
        for name, value in data.items()
        if name.endswith("types")
    }
    sections[section] = (source, orders)
    sources.DECLARATION_ORDER.write_text(render_json(sections), encoding="utf-8")


@pytest.fixture(scope="module")
def registry() -> TypeRegistry:
    return TypeRegistry(Dialect.ROS2)


@pytest.mark.parametrize("key", typed_keys())
def test_each_store_type_with_constants_keeps_its_files_order(
    registry: TypeRegistry, key: str
) -> None:
    path = installed_file(key, [INSTALLED_SHARE])
    if path is None:
        pytest.skip(f"no .msg file of {key} is installed under {INSTALLED_SHARE}")
    written = declared_names(path.read_text(encoding="utf-8"))
    assert declared_names(registry.message(key).definition_text()) == written


@pytest.mark.parametrize("key", sorted(EXPECTED))
def test_the_advertised_schema_keeps_the_files_order(registry: TypeRegistry, key: str) -> None:
    schema = schema_of(registry.message(key)).schema
    own_text = schema.split("\n" + "=" * 80 + "\n", 1)[0]
    assert declared_names(own_text) == EXPECTED[key]
    # rosapi hands out the same text
    assert registry.message(key).full_text() == schema


def test_the_packaged_order_is_what_the_installed_files_give() -> None:
    found = file_orders([INSTALLED_SHARE])
    if not found:
        pytest.skip(f"no .msg file of a store type with constants under {INSTALLED_SHARE}")
    packaged = sources.declaration_orders()
    assert {key: list(packaged[key]) for key in found if key in packaged} == found
    # each packaged order is a reordering of the store's own members
    for key, names in packaged.items():
        assert sorted(names) == sorted(store_order(key)), key


def test_an_order_that_does_not_fit_the_members_puts_constants_first() -> None:
    # as under another rosbags release, whose store may have other members
    fields = [FieldSpec("kind", FieldType("uint8")), FieldSpec("size", FieldType("float64"))]
    constants = [Constant("BIG", "uint8", 1)]
    fitting = sources.render_text(fields, constants, Dialect.ROS2, ["kind", "BIG", "size"])
    assert declared_names(fitting) == ["kind", "BIG", "size"]
    for order in (["kind", "BIG"], ["size", "BIG", "kind"], ["kind", "BIG", "size", "extra"]):
        text = sources.render_text(fields, constants, Dialect.ROS2, order)
        assert declared_names(text) == ["BIG", "kind", "size"]


if __name__ == "__main__":
    dirs = [INSTALLED_SHARE, *(Path(arg) for arg in sys.argv[1:])]
    write_section("types", "ROS 2 Kilted .msg files (common_interfaces 5.5)", file_orders(dirs))
