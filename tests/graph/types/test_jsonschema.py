"""A message type's JSON Schema (rwt_graph.types.jsonschema), as MCP tools and OpenAPI use it."""

from __future__ import annotations

from rwt_graph.types.jsonschema import json_schema

POSE = {
    "type": "geometry_msgs/Pose",
    "fieldnames": ["position", "_orientation"],
    "fieldtypes": ["geometry_msgs/Point", "geometry_msgs/Quaternion"],
    "fieldarraylen": [-1, -1],
}
POINT = {
    "type": "geometry_msgs/Point",
    "fieldnames": ["x", "y", "z"],
    "fieldtypes": ["float64", "float64", "float64"],
    "fieldarraylen": [-1, -1, -1],
}


def test_no_typedefs_is_an_empty_schema() -> None:
    assert json_schema([]) == {}


def test_nested_types_are_defs_referred_to_by_escaped_pointers() -> None:
    schema = json_schema([POSE, POINT])
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["title"] == "geometry_msgs/Pose"
    properties = schema["properties"]
    assert properties["position"] == {"$ref": "#/$defs/geometry_msgs~1Point"}
    # a type rosapi did not detail: any value, not a dangling reference
    assert properties["orientation"] == {}  # and the slot's leading _ dropped
    assert schema["$defs"]["geometry_msgs/Point"]["properties"]["x"] == {"type": "number"}


def test_primitives_arrays_bounds_and_bytes() -> None:
    typedef = {
        "type": "pkg/All",
        "fieldnames": ["flag", "count", "name", "short", "fixed", "any", "data", "chars"],
        "fieldtypes": ["bool", "int32", "string", "string<10>", "float32", "int8", "uint8", "char"],
        "fieldarraylen": [-1, -1, -1, -1, 3, 0, 0, 4],
    }
    properties = json_schema([typedef])["properties"]
    assert properties["flag"] == {"type": "boolean"}
    assert properties["count"] == {"type": "integer"}
    assert properties["name"] == {"type": "string"}
    assert properties["short"] == {"type": "string", "maxLength": 10}
    assert properties["fixed"] == {
        "type": "array",
        "items": {"type": "number"},
        "minItems": 3,
        "maxItems": 3,
    }
    assert properties["any"] == {"type": "array", "items": {"type": "integer"}}
    for octets in ("data", "chars"):  # base64 text or a list of 0-255, as rosbridge's JSON
        kinds = [option["type"] for option in properties[octets]["anyOf"]]
        assert kinds == ["string", "array"]


def test_missing_or_short_field_lists_are_read_as_far_as_they_go() -> None:
    typedef = {"type": "pkg/Odd", "fieldnames": ["a", "b"], "fieldtypes": ["int8", "int8"]}
    properties = json_schema([typedef, {"type": "pkg/Empty", "fieldnames": None}])["properties"]
    assert properties == {"a": {"type": "integer"}, "b": {"type": "integer"}}
