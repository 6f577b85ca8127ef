"""The parameter store from Python: ROS 2 node parameters and the ROS 1 tree (REF §7.1)."""

from __future__ import annotations

import copy
import math
import pickle

import pytest

from rwt_graph.graph import Graph
from rwt_graph.parameters.store import (
    ParameterError,
    ParameterNotSetError,
    Parameters,
    ParameterStoreFullError,
    to_json_safe,
    value_size,
)
from rwt_graph.types import Dialect, TypeRegistry

# ---- ROS 2 ---------------------------------------------------------------------------


def test_declared_parameters_are_named_node_colon_param() -> None:
    params = Graph().params
    params.declare("robot", {"max_speed": 1.5, "name": "r2", "wheels": [1, 2]})
    assert params.names() == ["/robot:max_speed", "/robot:name", "/robot:wheels"]
    assert params.get("/robot:max_speed") == 1.5
    assert params.get("robot:name") == "r2"  # the node resolves to /robot
    assert params.nodes() == {"/robot"}


def test_declared_type_is_kept_and_ints_widen_to_float() -> None:
    params = Parameters()
    params.declare("/n", {"speed": 0.5, "gains": [0.1, 0.2], "mode": "auto"})
    params.set("/n:speed", 2)
    assert params.get("/n:speed") == 2.0 and isinstance(params.get("/n:speed"), float)
    params.set("/n:gains", [1, 2.5])
    assert params.get("/n:gains") == (1.0, 2.5)
    params.set("/n:gains", [])
    assert params.get("/n:gains") == ()
    with pytest.raises(ParameterError, match="has type double, not string"):
        params.set("/n:speed", "fast")
    with pytest.raises(ParameterError, match="has type string, not integer"):
        params.set("/n:mode", 3)
    assert params.get("/n:mode") == "auto"


def test_undeclared_and_dynamically_typed_parameters_change_type() -> None:
    params = Parameters()
    params.set("/n:free", 1)
    params.set("/n:free", "one")
    params.declare("/n", {"dyn": True}, dynamic_typing=True)
    params.set("/n:dyn", [1, 2])
    assert params.get("/n:free") == "one" and params.get("/n:dyn") == (1, 2)


def test_read_only_parameters_refuse_set_and_delete() -> None:
    params = Parameters()
    params.declare("/robot", {"model": "turtle"}, read_only=True)
    with pytest.raises(ParameterError, match="read-only"):
        params.set("/robot:model", "hare")
    with pytest.raises(ParameterError, match="read-only"):
        params.delete("/robot:model")
    assert params.get("/robot:model") == "turtle"


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        ({"a": 1}, "not dict"),
        (None, "not NoneType"),
        ([1, "a"], "must have one type"),
        ([True, 1], "must have one type"),
        ([[1]], "not list"),
        (2**63, "does not fit in int64"),
        ("\ud800", "not valid Unicode"),
        (["ok", "\udfff"], "not valid Unicode"),
    ],
)
def test_values_ros2_cannot_hold_are_refused(value: object, problem: str) -> None:
    params = Parameters()
    with pytest.raises(ParameterError, match=problem):
        params.set("/n:p", value)
    assert not params.has("/n:p")


@pytest.mark.parametrize("name", ["no_colon", ":p", "/n:", "/n:a:b", "/9bad:p", "/n-1:p"])
def test_malformed_ros2_names_are_refused(name: str) -> None:
    params = Parameters()
    with pytest.raises(ParameterError):
        params.set(name, 1)
    assert params.has(name) is False


def test_get_default_has_and_delete() -> None:
    params = Parameters()
    with pytest.raises(ParameterNotSetError):
        params.get("/n:p")
    assert params.get("/n:p", 7) == 7
    params.set("/n:p", 1)
    assert params.has("/n:p")
    params.delete("/n:p")
    assert not params.has("/n:p") and params.nodes() == set()
    with pytest.raises(ParameterNotSetError):
        params.delete("/n:p")


def test_values_are_held_frozen_and_shared_not_copied() -> None:
    params = Parameters(Dialect.ROS2)
    mine = [1, 2]
    params.set("/n:list", mine)
    mine.append(3)  # the caller's list is not the store's
    got = params.get("/n:list")
    assert got == (1, 2) and params.get("/n:list") is got  # the held value, every time
    seen: list[object] = []
    params.watch(lambda name, value: seen.append(value))
    params.watch(lambda name, value: seen.append(value))
    params.set("/n:list", list(range(1000)))
    assert seen[0] is seen[1] is params.get("/n:list")  # one object for every watcher
    tree = ros1()
    tree.set("/arm", {"joints": [1, 2], "name": "ur5"})
    arm = tree.get("/arm")
    assert arm == {"joints": (1, 2), "name": "ur5"} and tree.get("/arm") is arm
    with pytest.raises(TypeError, match="cannot be changed"):
        arm["name"] = "other"  # type: ignore[index]
    with pytest.raises(TypeError, match="cannot be changed"):
        arm.update(name="other")  # type: ignore[attr-defined]
    tree.set("/arm/name", "ur10")
    assert arm == {"joints": (1, 2), "name": "ur5"}  # what a reader got stays as it was
    assert tree.get("/arm") == {"joints": (1, 2), "name": "ur10"}
    assert copy.deepcopy(arm) is arm and pickle.loads(pickle.dumps(arm)) == arm


def test_watchers_hear_sets_and_deletes_until_stopped() -> None:
    params = Parameters()
    seen: list[tuple[str, object]] = []
    stop = params.watch(lambda name, value: seen.append((name, value)))

    def broken(name: str, value: object) -> None:
        raise RuntimeError("watcher bug")

    params.watch(broken)
    params.declare("n", {"a": 1})
    params.set("/n:a", 2)
    params.delete("/n:a")
    stop()
    params.set("/n:b", 3)
    assert seen == [("/n:a", 1), ("/n:a", 2), ("/n:a", None)]


def test_a_watcher_of_one_name_hears_that_name_alone() -> None:
    params = Parameters()
    heard: list[tuple[str, object]] = []
    stop = params.watch(lambda name, value: heard.append((name, value)), key="/n:speed")
    params.set("/n:speed", 1.5)
    params.set("/n:other", 2)  # not called at all for another name
    params.delete("/n:speed")
    stop()
    params.set("/n:speed", 3.0)
    assert heard == [("/n:speed", 1.5), ("/n:speed", None)]


def test_large_arrays_are_checked_whole_and_a_bad_item_is_named() -> None:
    params = Parameters(max_bytes=64 * 1024 * 1024, node_share=1)
    params.set("/n:ints", list(range(1_000_000)))
    assert params.get("/n:ints")[-1] == 999_999  # type: ignore[index]
    with pytest.raises(ParameterError, match=r"integer 9223372036854775808 does not fit"):
        params.set("/n:ints", [*range(1000), 2**63])
    with pytest.raises(ParameterError, match="not valid Unicode"):
        params.set("/n:texts", ["ok"] * 1000 + ["\ud800"])
    with pytest.raises(ParameterError, match="must have one type"):
        params.set("/n:mixed", [1, True])
    params.set("/n:doubles", [1, 2.5, *range(1000)])  # ints among floats: a double array
    assert set(map(type, params.get("/n:doubles"))) == {float}  # type: ignore[arg-type]
    info = params.describe("/n:doubles")
    assert info is not None and info.kind == "double_array"
    assert params.get("/n:ints") == tuple(range(1_000_000))  # the refused sets changed nothing


def test_the_store_is_bounded() -> None:
    params = Parameters(max_params=2, node_share=1)  # the share is tested below
    params.set("/n:a", 1)
    params.set("/n:b", 1)
    params.set("/n:a", 2)  # replacing is fine
    with pytest.raises(ParameterError, match="full"):
        params.set("/n:c", 1)


def test_one_node_holds_at_most_its_share_and_the_others_keep_their_room() -> None:
    params = Parameters(max_params=8, max_bytes=800, node_share=0.5)
    assert (params.max_node_params, params.max_node_bytes) == (4, 400)
    for n in range(4):
        params.set(f"/big:p{n}", n)
    assert params.room("/big") == 0
    assert params.room_problem("big") == (
        "node /big holds its share of the parameter store (4 parameters)"
    )
    with pytest.raises(ParameterStoreFullError, match=r"node /big holds its share .*4 param"):
        params.set("/big:p4", 4)
    with pytest.raises(ParameterStoreFullError, match="node /big holds its share"):
        params.declare("big", {"p5": 5})
    with pytest.raises(ParameterStoreFullError, match="node /big holds its share"):
        params.set_all([("/big:p0", None), ("/big:p4", 4), ("/big:p5", 5)])
    params.set("/big:p0", "changed")  # a change of a held parameter is no new one
    params.set_all([("/big:p0", None), ("/big:p4", 4)])  # one goes, one comes
    assert params.names()[:4] == ["/big:p1", "/big:p2", "/big:p3", "/big:p4"]
    params.set("/other:a", 1)  # the rest of the store is the other nodes'
    assert params.room("/other") == 3
    assert params.room_problem("/other") is None
    params.delete("/big:p1")
    assert params.room("/big") == 1


def test_one_nodes_values_hold_at_most_its_share_of_the_bytes() -> None:
    params = Parameters(max_bytes=800, node_share=0.5)
    params.set("/big:a", "x" * 300)
    with pytest.raises(ParameterStoreFullError, match=r"node /big holds its share .*400 bytes"):
        params.set("/big:b", "y" * 200)
    with pytest.raises(ParameterStoreFullError, match=r"400 bytes"):
        params.set("/big:a", "x" * 401)
    with pytest.raises(ParameterStoreFullError, match=r"400 bytes"):
        params.set_all([("/big:b", "y" * 200)])
    assert params.names() == ["/big:a"]
    params.set("/other:a", "z" * 400)  # another node's room is untouched
    params.delete("/big:a")
    params.set("/big:b", "y" * 400)  # deleting freed the node's room
    assert params.get("/big:b") == "y" * 400


def test_set_all_makes_every_change_or_none() -> None:
    params = Parameters(max_params=3, max_bytes=64, node_share=1)
    params.declare("n", {"rate": 1.5})
    params.declare("n", {"id": 7}, read_only=True)
    seen: list[tuple[str, object]] = []
    params.watch(lambda name, value: seen.append((name, value)))
    refusals = [
        ([("/n:mode", "x"), ("/n:rate", "fast")], "has type double, not string"),
        ([("/n:mode", "x"), ("/n:id", 8)], "read-only"),
        ([("/n:mode", "x"), ("/n:id", None)], "read-only"),
        ([("/n:mode", "x"), ("/n:nope", None)], "/n:nope is not set"),
        ([("/n:mode", "x"), ("/n:a:b", 1)], "expected <node>:<parameter>"),
        ([("/n:mode", "x"), ("/n:more", 1)], r"full \(3 parameters\)"),
        ([("/n:mode", "x" * 60)], r"full \(64 bytes\)"),
    ]
    for changes, problem in refusals:
        with pytest.raises(ParameterError, match=problem):
            params.set_all(changes)
    assert params.names() == ["/n:id", "/n:rate"]
    assert seen == []
    # later changes see earlier ones; an int fits the declared double
    params.set_all([("/n:mode", "x"), ("/n:mode", None), ("/n:rate", 2), ("/n:mode", "y")])
    assert (params.get("/n:rate"), params.get("/n:mode")) == (2.0, "y")
    assert seen == [("/n:mode", "y"), ("/n:rate", 2.0)]
    info = params.describe("/n:rate")
    assert info is not None
    assert (info.kind, info.read_only, info.dynamic_typing) == ("double", False, False)
    assert params.describe("/n:absent") is None
    params.set_all([("/n:mode", None)])  # frees its room
    params.set_all([("/n:a", 1)])


def test_byte_arrays_are_bytes_of_their_own_kind() -> None:
    params = Parameters(max_bytes=1000, node_share=1)
    params.declare("/n", {"blob": b"\x00\xff", "ids": [1, 2]})
    params.set("/n:free", bytearray(b"ab"))
    assert params.get("/n:blob") == b"\x00\xff" and params.get("/n:free") == b"ab"
    info = params.describe("/n:blob")
    assert info is not None and info.kind == "byte_array"
    # a list of octets is that byte array (what rosapi's JSON carries); [] is empty
    params.set("/n:blob", [1, 2, 3])
    assert params.get("/n:blob") == b"\x01\x02\x03"
    params.set("/n:blob", [])
    assert params.get("/n:blob") == b""
    for other, kind in ([1, 256], "integer_array"), ("x", "string"), ([True], "bool_array"):
        with pytest.raises(ParameterError, match=f"has type byte_array, not {kind}"):
            params.set("/n:blob", other)
    with pytest.raises(ParameterError, match="has type integer_array, not byte_array"):
        params.set("/n:ids", b"\x01")
    params.set("/n:free", [1, 2])  # dynamic typing: now an integer array
    assert params.get("/n:free") == (1, 2)
    with pytest.raises(ParameterError, match="not bytes"):
        params.set("/n:p", [b"\x01"])  # rclpy's list of single bytes is no value here


def test_a_byte_array_counts_its_length() -> None:
    params = Parameters(max_bytes=100, node_share=1)
    params.set("/n:blob", bytes(100))
    with pytest.raises(ParameterStoreFullError, match=r"full \(100 bytes\)"):
        params.set("/n:more", b"\x01")
    params.set("/n:blob", bytes(10))
    params.set("/n:more", bytes(90))
    assert value_size(b"abc") == 3


def test_a_byte_array_is_json_octets() -> None:
    assert to_json_safe([1.0, math.inf]) == [1.0, None]
    assert to_json_safe(b"\x00\x01\xff") == [0, 1, 255]


# ---- ROS 1 ---------------------------------------------------------------------------


def ros1() -> Parameters:
    return Graph(TypeRegistry(Dialect.ROS1)).params


def test_ros1_names_are_global_and_namespaces_are_dicts() -> None:
    params = ros1()
    params.set("/robot/speed", 1.5)
    params.set("robot/arm", {"joints": 6, "names": ["a", 1, True]})
    assert params.names() == ["/robot/arm/joints", "/robot/arm/names", "/robot/speed"]
    assert params.get("/robot") == {
        "speed": 1.5,
        "arm": {"joints": 6, "names": ("a", 1, True)},
    }
    assert params.has("/robot/arm") and not params.has("/robot/leg")
    params.delete("/robot/arm")
    assert params.names() == ["/robot/speed"]
    with pytest.raises(ParameterNotSetError):
        params.delete("/robot/arm")


def test_ros1_declare_uses_the_node_namespace_and_search_finds_globals() -> None:
    params = ros1()
    params.declare("/camera", {"fps": 30})
    assert params.get("/camera/fps") == 30
    assert params.search("camera/fps") == "/camera/fps"
    assert params.search("nothing") == ""


def test_ros1_a_leaf_a_namespace_replaces_gives_back_its_bytes() -> None:
    params = Parameters(Dialect.ROS1, max_bytes=150)
    params.set("/a", "x" * 100)
    params.set("/a/b", 1)  # /a is now a namespace: its 100 bytes are free again
    params.set("/c", "y" * 100)
    assert params.get("/") == {"a": {"b": 1}, "c": "y" * 100}
    params.delete("/a/b")  # an empty namespace stays, and counts as one parameter
    assert params.get("/a") == {} and params.names() == ["/c"]


def test_ros1_setting_under_a_value_makes_it_a_namespace() -> None:
    params = ros1()
    params.set("/a", 1)
    params.set("/a/b", 2)
    assert params.get("/a") == {"b": 2}
    params.set("/", {"x": 1})
    assert params.names() == ["/x"]
    with pytest.raises(ParameterError, match="only be set to a dict"):
        params.set("/", 3)


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        (None, "cannot be NoneType"),
        (2**31, "int32"),
        (b"\x01", "cannot be bytes"),
        ({"a/b": 1}, "namespace keys"),
        ({"a": ["\ud800"]}, "not valid Unicode"),
        ({"\ud800": 1}, "not valid Unicode"),
    ],
)
def test_ros1_refuses_what_xmlrpc_cannot_carry(value: object, problem: str) -> None:
    with pytest.raises(ParameterError, match=problem):
        ros1().set("/p", value)


def test_ros1_store_bound_counts_leaves() -> None:
    params = Parameters(Dialect.ROS1, max_params=3)
    params.set("/ns", {"a": 1, "b": 2})
    params.set("/ns", {"a": 1, "b": 2, "c": 3})  # replaces two leaves by three
    with pytest.raises(ParameterError, match="full"):
        params.set("/other", 1)


def test_nan_is_kept_in_python() -> None:
    params = Parameters()
    params.set("/n:x", math.nan)
    value = params.get("/n:x")
    assert isinstance(value, float) and math.isnan(value)


@pytest.mark.parametrize("dialect", [Dialect.ROS2, Dialect.ROS1])
def test_the_values_bytes_are_bounded_and_freed(dialect: Dialect) -> None:
    # A client could otherwise fill max_params parameters with max-size strings.
    params = Parameters(dialect, max_bytes=1000, node_share=1)
    name = "/n:p{}" if dialect is Dialect.ROS2 else "/n/p{}"
    params.set(name.format(1), "x" * 600)
    with pytest.raises(ParameterError, match="full \\(1000 bytes\\)"):
        params.set(name.format(2), "y" * 600)
    assert not params.has(name.format(2))
    params.set(name.format(1), "z" * 900)  # replacing counts the difference
    with pytest.raises(ParameterError, match="full"):
        params.set(name.format(1), "z" * 1001)
    params.delete(name.format(1))
    params.set(name.format(2), "y" * 990)  # deleting freed the room
    assert params.get(name.format(2)) == "y" * 990
