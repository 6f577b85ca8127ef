"""What ``rwt mcp`` hands an agent, bounded: message text, JSON schemas, images.

The tools' text, schemas and images come from ``rwt_mcp.render`` (sans-IO); these
check its bounds with messages past them, and the JSON schema of real message
types (the graph's rosapi typedefs, as ``message_details`` answers them) against
messages built by hand, with the ``jsonschema`` validator where it is installed.
"""

from __future__ import annotations

import io
import json

import pybase64
import pytest
from PIL import Image

from rwt_graph.media.images import ImageError
from rwt_graph.rosapi.typedefs import typedefs
from rwt_graph.types import TypeRegistry

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from rwt_mcp.render import (
    MAX_ARRAY_ITEMS,
    MAX_DECODE_PIXELS,
    MAX_IMAGE_BYTES,
    MAX_IMAGE_SIDE,
    MAX_MESSAGE_CHARS,
    MAX_STRING_CHARS,
    encode_image,
    json_schema,
    message_text,
    summarise,
)
from rwt_mcp.tools import MAX_ECHO_CHARS, RobotTools


def test_long_arrays_strings_and_bytes_are_summarised_short_ones_kept() -> None:
    msg = {
        "ranges": [0.5] * (MAX_ARRAY_ITEMS + 1),
        "ids": list(range(MAX_ARRAY_ITEMS)),
        "data": b"\x00" * 921600,
        "name": "x" * (MAX_STRING_CHARS + 10),
        "poses": [{"x": 1}] * 100,
    }
    shown = summarise(msg)
    assert shown == {
        "ranges": f"<float[{MAX_ARRAY_ITEMS + 1}]>",
        "ids": list(range(MAX_ARRAY_ITEMS)),
        "data": "<uint8[921600]>",
        "name": "x" * MAX_STRING_CHARS + f"...<{MAX_STRING_CHARS + 10} chars>",
        "poses": "<object[100]>",
    }


def test_a_message_text_is_cut_at_its_bound_and_says_so() -> None:
    many = {f"field_{i}": "y" * 100 for i in range(100)}  # ~11 000 characters of JSON
    text = message_text(many)
    assert len(text) < MAX_MESSAGE_CHARS + 40
    assert text.endswith(f"...<cut: {len(json.dumps(many))} chars>")
    assert json.loads(message_text({"data": "ok"})) == {"data": "ok"}


@pytest.mark.anyio
async def test_an_echo_stops_adding_messages_past_its_total() -> None:
    big = {"data": "z" * MAX_STRING_CHARS}  # each ~530 characters as text
    messages = [big] * 100
    content = await RobotTools._echoed("/t", "std_msgs/msg/String", messages, False, True)
    texts = [block.text for block in content[1:]]  # type: ignore[union-attr]
    assert sum(len(text) for text in texts) <= MAX_ECHO_CHARS
    assert 0 < len(texts) < 100
    assert json.loads(content[0].text)["received"] == 100  # type: ignore[union-attr]


def _schema(type_name: str) -> dict[str, object]:
    registry = TypeRegistry()  # ROS 2's types, as rosapi's message_details gives them
    return json_schema(typedefs(registry.message(type_name), registry.message))


def test_the_schema_of_an_image_takes_base64_or_bytes_and_its_header() -> None:
    schema = _schema("sensor_msgs/msg/Image")
    props = schema["properties"]
    assert isinstance(props, dict)
    assert props["data"]["anyOf"][0] == {"type": "string", "contentEncoding": "base64"}
    assert props["width"] == {"type": "integer"}
    assert props["is_bigendian"] == {"type": "integer"}  # uint8, not bool
    header = props["header"]["$ref"].removeprefix("#/$defs/").replace("~1", "/")
    defs = schema["$defs"]
    assert isinstance(defs, dict)
    assert defs[header]["properties"]["frame_id"] == {"type": "string"}


def test_a_schema_validates_what_rosbridge_takes_and_refuses_what_it_does_not() -> None:
    jsonschema = pytest.importorskip("jsonschema", reason="a JSON schema validator")
    validator = jsonschema.Draft202012Validator(_schema("geometry_msgs/msg/Twist"))
    assert validator.is_valid({"linear": {"x": 0.2}, "angular": {"z": -0.5}})
    assert not validator.is_valid({"linear": {"x": "fast"}})
    fixed = jsonschema.Draft202012Validator(_schema("geometry_msgs/msg/PoseWithCovariance"))
    assert fixed.is_valid({"covariance": [0.0] * 36})
    assert not fixed.is_valid({"covariance": [0.0] * 35})  # float64[36]


def _image(width: int, height: int) -> dict[str, object]:
    pixels = bytes(range(256)) * (width * height * 3 // 256 + 1)
    data = pixels[: width * height * 3]
    return {"encoding": "rgb8", "width": width, "height": height, "step": width * 3, "data": data}


def test_a_raw_image_as_png_scaled_down_to_its_bound() -> None:
    msg = _image(MAX_IMAGE_SIDE * 2, 10)
    msg["data"] = pybase64.b64encode(msg["data"]).decode()  # as rosbridge's JSON sends it
    data, mime = encode_image(msg, "sensor_msgs/msg/Image")
    assert mime == "image/png"
    assert Image.open(io.BytesIO(data)).size == (MAX_IMAGE_SIDE, 5)


def _jpeg(width: int, height: int) -> bytes:
    out = io.BytesIO()
    Image.new("RGB", (width, height), (0, 128, 255)).save(out, "JPEG")
    return out.getvalue()


def test_a_small_compressed_image_passes_as_it_is_a_large_one_is_reencoded() -> None:
    small = _jpeg(64, 48)
    assert encode_image({"format": "jpeg", "data": small}, "sensor_msgs/CompressedImage") == (
        small,
        "image/jpeg",
    )
    large = _jpeg(MAX_IMAGE_SIDE * 3, 100)
    data, mime = encode_image({"format": "jpeg", "data": large}, "sensor_msgs/CompressedImage")
    assert mime == "image/jpeg" and data != large
    assert max(Image.open(io.BytesIO(data)).size) <= MAX_IMAGE_SIDE
    assert len(data) <= MAX_IMAGE_BYTES


def test_images_that_cannot_be_shown_are_errors() -> None:
    with pytest.raises(ImageError, match="unknown compressed image format"):
        encode_image({"format": "tiff", "data": b"x"}, "sensor_msgs/CompressedImage")
    with pytest.raises(ImageError, match="cannot be read"):
        encode_image({"format": "png", "data": b"not a png"}, "sensor_msgs/CompressedImage")
    with pytest.raises(ImageError, match="unsupported image encoding"):
        encode_image({**_image(2, 2), "encoding": "yuv422"}, "sensor_msgs/msg/Image")
    # a PNG header claiming 8000x8000 pixels: refused before any decoding
    header = io.BytesIO()
    Image.new("1", (8000, 8000)).save(header, "PNG")
    assert MAX_DECODE_PIXELS < 8000 * 8000
    with pytest.raises(ImageError, match=f"over {MAX_DECODE_PIXELS} pixels"):
        encode_image({"format": "png", "data": header.getvalue()}, "sensor_msgs/CompressedImage")


def test_the_schema_of_rosbridge_suite_2_1_slot_names_has_the_field_names() -> None:
    # rosbridge_suite 2.1.0's message_details on ROS 2 Kilted, as it answered (docs/agents.md)
    answered = [
        {
            "type": "geometry_msgs/Twist",
            "fieldnames": ["_linear", "_angular"],
            "fieldtypes": ["geometry_msgs/Vector3", "geometry_msgs/Vector3"],
            "fieldarraylen": [-1, -1],
        },
        {
            "type": "geometry_msgs/Vector3",
            "fieldnames": ["_x", "_y", "_z"],
            "fieldtypes": ["float64", "float64", "float64"],
            "fieldarraylen": [-1, -1, -1],
        },
    ]
    schema = json_schema(answered)
    assert set(schema["properties"]) == {"linear", "angular"}  # type: ignore[arg-type]
    vector = schema["$defs"]["geometry_msgs/Vector3"]  # type: ignore[index]
    assert set(vector["properties"]) == {"x", "y", "z"}
