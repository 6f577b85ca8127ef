"""The .msg/.srv/.action parser: defaults, constants, bounds, comments (D7)."""

from __future__ import annotations

from pathlib import Path

import pytest

from rwt_graph.types import (
    ArrayKind,
    Constant,
    DefinitionError,
    Dialect,
    FieldType,
    TypeRegistry,
    UnknownTypeError,
    parse_message,
)


def parse(text: str, dialect: Dialect = Dialect.ROS2, package: str = "pkg") -> object:
    return parse_message(text, package=package, dialect=dialect)


def test_defaults_are_parsed_into_the_internal_form(ros2: TypeRegistry) -> None:
    mtype = ros2.message("rwt_test_msgs/Defaults")
    defaults = {spec.name: spec.default for spec in mtype.fields}
    assert defaults == {
        "count": 42,
        "gain": 0.5,
        "active": True,
        "label": "the # is kept",
        "levels": [1, -2, 3],
        "names": ["a", "b, c"],
        "raw": b"\x01\x02\xff",
        "plain": None,
    }
    assert mtype.default() == {
        "count": 42,
        "gain": 0.5,
        "active": True,
        "label": "the # is kept",
        "levels": [1, -2, 3],
        "names": ["a", "b, c"],
        "raw": b"\x01\x02\xff",
        "plain": 0.0,
    }


def test_default_lists_are_fresh_copies(ros2: TypeRegistry) -> None:
    mtype = ros2.message("rwt_test_msgs/Defaults")
    first = mtype.default()
    first["levels"].append(9)  # type: ignore[attr-defined]
    assert mtype.default()["levels"] == [1, -2, 3]


def test_constants_with_comments_depend_on_the_dialect(
    ros2: TypeRegistry, ros1: TypeRegistry
) -> None:
    assert ros2.message("rwt_test_msgs/Defaults").constants == (
        Constant("RED", "int32", 1),
        Constant("GREETING", "string", "hello"),
        Constant("PI", "float64", 3.14159),
        Constant("ENABLED", "bool", True),
    )
    # ROS 1: everything after '=' is a string constant's value.
    greeting = ros1.message("rwt_test_msgs/Defaults").constants[1]
    assert greeting.value == "hello # a comment after a constant"


def test_field_kinds_and_bounds(ros2: TypeRegistry) -> None:
    types = {spec.name: spec.type for spec in ros2.message("rwt_test_msgs/Limits").fields}
    assert types["uuid"] == FieldType("uint8", False, ArrayKind.FIXED, 16)
    assert types["small_bytes"] == FieldType("uint8", False, ArrayKind.BOUNDED, 4)
    assert types["chars"] == FieldType("char", False, ArrayKind.UNBOUNDED)
    assert types["short_name"] == FieldType("string", string_bound=5)
    assert types["tags"] == FieldType("string", False, ArrayKind.BOUNDED, 2, 3)
    assert types["tags"].spelled() == "string<=3[<=2]"


def test_type_names_inside_definitions_resolve_like_ros() -> None:
    parsed = parse(
        "Header a\nPoint b\ngeometry_msgs/Pose c\ngeometry_msgs/msg/Pose[] d\n"
        "time t\nduration u\nbuiltin_interfaces/Time v",
        package="geometry_msgs",
    )
    bases = [(f.name, f.type.base, f.type.is_message) for f in parsed.fields]  # type: ignore[attr-defined]
    assert bases == [
        ("a", "std_msgs/msg/Header", True),
        ("b", "geometry_msgs/msg/Point", True),
        ("c", "geometry_msgs/msg/Pose", True),
        ("d", "geometry_msgs/msg/Pose", True),
        ("t", "builtin_interfaces/msg/Time", True),
        ("u", "builtin_interfaces/msg/Duration", True),
        ("v", "builtin_interfaces/msg/Time", True),
    ]
    ros1 = parse(
        "Header a\ntime t\nbuiltin_interfaces/Duration u\nbuiltin_interfaces/Other o", Dialect.ROS1
    )
    assert [(f.type.base, f.type.is_message) for f in ros1.fields] == [  # type: ignore[attr-defined]
        ("std_msgs/Header", True),
        ("time", False),
        ("duration", False),
        ("builtin_interfaces/Other", True),
    ]


def test_comments_and_blank_lines_are_ignored_and_text_is_kept() -> None:
    text = "# leading comment\n\n  int32 a   # trailing\n#int32 b\nstring c 'x#y' # z\n"
    parsed = parse(text)
    assert [(f.name, f.default) for f in parsed.fields] == [("a", None), ("c", "x#y")]  # type: ignore[attr-defined]
    assert parsed.text == text  # type: ignore[attr-defined]


def test_more_literal_forms() -> None:
    parsed = parse(
        'int32 H=0x10\nint8 N=-5\nbool F=False\nbool T=1\nstring Q="a\\"b"\n'
        'float32 e 1e3\nbool[2] pair [true, false]\nint32[] none []\nwstring w "hi"\n'
        "string[] bare [x, y z]"
    )
    assert [c.value for c in parsed.constants] == [16, -5, False, True, 'a"b']  # type: ignore[attr-defined]
    assert [f.default for f in parsed.fields] == [  # type: ignore[attr-defined]
        1000.0,
        [True, False],
        [],
        "hi",
        ["x", "y z"],
    ]  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("int32", "expected 'TYPE NAME', got 'int32'"),
        ("int32 a\nint32 a", "'a' declared twice"),
        ("uint8 a 256", "bad default '256': expected uint8 in [0, 255], got 256"),
        ("int32 a 1.5", "bad default '1.5': invalid literal"),
        ("bool a maybe", "bad default 'maybe': not a bool: 'maybe'"),
        ("int32[3] a [1, 2]", "bad default '[1, 2]': expected 3 elements, got 2"),
        ("int32[] a 1", "bad default '1': expected [a, b, ...], got '1'"),
        ("std_msgs/Header h 1", "only primitive fields may have a default"),
        ("int32[] X=1", "constants must have a primitive, non-array type"),
        ("int8 X=200", "bad constant '200': expected int8 in [-128, 127], got 200"),
        ("int32<=3 a", "only strings have a bound: 'int32<=3'"),
        ("int32[<=] a", "bounded array without a bound: 'int32[<=]'"),
        ("a/b/c/d x", "malformed type 'a/b/c/d'"),
        ("int32[x] a", "malformed type 'int32[x]'"),
        ("string[] a [1, 2]", "bad default '[1, 2]': expected an array of strings"),
        ("float32 f 1e39", "bad default '1e39': expected float32"),
    ],
)
def test_definition_errors_name_the_line(text: str, problem: str) -> None:
    with pytest.raises(DefinitionError) as caught:
        parse_message(text, package="pkg", dialect=Dialect.ROS2, origin="Bad.msg")
    line = len(text.splitlines())
    assert caught.value.message.startswith(f"Bad.msg:{line}: {problem}")


def test_service_and_action_parts_split_at_separators(tmp_path: Path) -> None:
    srv = tmp_path / "pkg" / "srv"
    srv.mkdir(parents=True)
    (srv / "Two.srv").write_text("# request\nint32 a\n  ---  \nstring b\n")
    (srv / "Bad.srv").write_text("int32 a\n---\nint32 b\n---\nint32 c\n")
    registry = TypeRegistry(interface_dirs=[tmp_path])
    service = registry.service("pkg/Two")
    assert service.request.definition_text() == "# request\nint32 a\n"
    assert service.response.definition_text() == "string b\n"
    with pytest.raises(DefinitionError, match=r"Bad.srv:0: expected 2 parts separated by ---"):
        registry.service("pkg/Bad")


def test_unknown_and_recursive_dependencies(tmp_path: Path) -> None:
    msg = tmp_path / "pkg" / "msg"
    msg.mkdir(parents=True)
    (msg / "Dangling.msg").write_text("Missing m\n")
    (msg / "A.msg").write_text("B b\n")
    (msg / "B.msg").write_text("A a\n")
    registry = TypeRegistry(interface_dirs=[tmp_path])
    with pytest.raises(UnknownTypeError, match=r"unknown message type 'pkg/msg/Missing'"):
        registry.message("pkg/Dangling")
    with pytest.raises(DefinitionError, match=r"uses itself"):
        registry.message("pkg/A")
