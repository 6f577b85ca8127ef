"""Every type hash rwt computes equals the one real rosidl generated.

The ROS 2 Kilted wheels on PyPI (``ros-kilted-*-msgs``, ``ros-kilted-test-msgs``,
installed by the test extra) ship rosidl_generator_type_description's output:
``<prefix>/share/<pkg>/{msg,srv,action}/<Name>.json``, each listing the RIHS01
hashes of the type and of its generated parts. Each shipped type of rwt is
compared with them, and so is every type of the installed packages, rwt reading
their ``.msg``/``.srv``/``.action`` files as ``--interfaces`` does.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from rwt_graph.types.registry import TypeRegistry
from rwt_protocol.errors import RwtError
from rwt_zenoh.actions import ActionWire
from rwt_zenoh.payload import message_hash, named_service_hash, service_hash, type_hash

SHARE = Path(sys.prefix) / "share"
GENERATED = sorted(SHARE.glob("*/msg/*.json")) + sorted(SHARE.glob("*/srv/*.json"))
ACTIONS = sorted(SHARE.glob("*/action/*.json"))

pytestmark = pytest.mark.skipif(
    not (SHARE / "test_msgs" / "msg" / "WStrings.json").exists(),
    reason="the ROS 2 Kilted interface wheels are not installed (pip install -e '.[test]')",
)


def rosidl_hashes(files: list[Path]) -> dict[str, str]:
    """type name -> the hash rosidl generated, for every part each file lists."""
    hashes: dict[str, str] = {}
    for path in files:
        for entry in json.loads(path.read_text())["type_hashes"]:
            hashes[entry["type_name"]] = entry["hash_string"]
    return hashes


def own_hash(registry: TypeRegistry, name: str) -> str | None:
    """rwt's hash of a message or service ``name``; None for a type rwt cannot read."""
    try:
        if "/srv/" in name and not name.endswith(("_Request", "_Response", "_Event")):
            return service_hash(registry, registry.service(name))
        if name.endswith("_Event"):
            return None  # hashed inside its service's description, never on its own
        return type_hash(registry, name)
    except RwtError:
        return None


def test_every_type_rwt_ships_hashes_as_rosidl_does() -> None:
    registry = TypeRegistry()
    expected = rosidl_hashes(GENERATED)
    compared = {n: own_hash(registry, n) for n in expected}
    compared = {n: h for n, h in compared.items() if h is not None}
    assert len(compared) > 100  # std_msgs through sensor_msgs at least
    assert {n: h for n, h in compared.items() if h != expected[n]} == {}


def test_every_installed_type_read_as_interfaces_hashes_as_rosidl_does() -> None:
    # test_msgs covers every field kind: wstring (WStrings), bounded strings and
    # sequences, fixed arrays, constants, nested and empty messages
    registry = TypeRegistry(interface_dirs=[SHARE])
    expected = rosidl_hashes(GENERATED)
    compared = {n: own_hash(registry, n) for n in expected}
    unread = sorted(n for n, h in compared.items() if h is None and not n.endswith("_Event"))
    # rosidl's .idl-only keyed types have no .msg file: nothing else may be missing
    assert all("Keyed" in n or "NestedKey" in n for n in unread), unread
    wrong = {n: h for n, h in compared.items() if h is not None and h != expected[n]}
    assert wrong == {}
    assert compared["test_msgs/msg/WStrings"] == expected["test_msgs/msg/WStrings"]


def test_action_parts_hash_as_rosidl_does() -> None:
    registry = TypeRegistry(interface_dirs=[SHARE])
    expected = rosidl_hashes(ACTIONS)
    checked = 0
    for name in expected:
        if "/action/" not in name or "_" in name.rpartition("/")[2]:
            continue  # a part: the action itself is named pkg/action/Name
        ActionWire(registry, registry.action(name))  # registers its wrappers
        for part, hashed in (
            ("_SendGoal", named_service_hash(registry, name + "_SendGoal")),
            ("_GetResult", named_service_hash(registry, name + "_GetResult")),
            ("_FeedbackMessage", message_hash(registry, name + "_FeedbackMessage")),
        ):
            assert hashed == expected[name + part], name + part
            checked += 1
    assert checked >= 6  # test_msgs' Fibonacci and NestedMessage
