"""What the MCP tools hand an agent: bounded message text, JSON schemas and images.

No I/O: messages in (as the rosbridge client decoded them), text, schemas and
encoded images out. Every bound is a constant here, listed in docs/limits.md
("MCP front end").
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping
from typing import Any

import pybase64
from PIL import Image

from rwt_graph.media.compressed import MAX_DECODE_PIXELS, open_compressed
from rwt_graph.media.images import ImageError, compressed_content_type, image_to_display
from rwt_graph.types.jsonschema import json_schema

__all__ = [
    "IMAGE_TYPES",
    "MAX_ARRAY_ITEMS",
    "MAX_DECODE_PIXELS",
    "MAX_IMAGE_BYTES",
    "MAX_IMAGE_SIDE",
    "MAX_MESSAGE_CHARS",
    "MAX_STRING_CHARS",
    "encode_image",
    "json_schema",
    "message_text",
    "summarise",
]

#: A list longer than this is replaced by a summary such as ``<int[921600]>``.
MAX_ARRAY_ITEMS = 64
#: A string longer than this is cut, its length kept: ``"abc...<5000 chars>"``.
MAX_STRING_CHARS = 512
#: One message as JSON text, after summarising: longer text is cut and says so.
MAX_MESSAGE_CHARS = 4000
#: An image's longer side is scaled down to this many pixels before encoding.
MAX_IMAGE_SIDE = 1024
#: A ``CompressedImage`` larger than this is re-encoded (as JPEG, scaled down).
MAX_IMAGE_BYTES = 2 * 1024 * 1024
# MAX_DECODE_PIXELS: the pixels of a ``CompressedImage`` decoded at most, the rule of
# every front end (``rwt_graph.media.compressed``); a larger one is a tool error
#: The message types returned as MCP image content, both dialects' spellings.
IMAGE_TYPES = frozenset(
    {
        "sensor_msgs/Image",
        "sensor_msgs/msg/Image",
        "sensor_msgs/CompressedImage",
        "sensor_msgs/msg/CompressedImage",
    }
)
_JPEG_QUALITY = 85


def summarise(value: object) -> object:
    """``value`` with long lists, long strings and bytes replaced by short summaries.

    Lists over ``MAX_ARRAY_ITEMS`` become ``"<KIND[N]>"`` (KIND: ``int``,
    ``float``, ``bool``, ``str``, ``object``, ``mixed``), bytes ``"<uint8[N]>"``,
    strings over ``MAX_STRING_CHARS`` their start and ``...<N chars>``.
    """
    if isinstance(value, Mapping):
        return {str(key): summarise(item) for key, item in value.items()}
    if isinstance(value, bytes | bytearray | memoryview):
        return f"<uint8[{len(value)}]>"
    if isinstance(value, str) and len(value) > MAX_STRING_CHARS:
        return f"{value[:MAX_STRING_CHARS]}...<{len(value)} chars>"
    if isinstance(value, list | tuple):
        if len(value) > MAX_ARRAY_ITEMS:
            return f"<{_kind(value)}[{len(value)}]>"
        return [summarise(item) for item in value]
    return value


def _kind(items: list[Any] | tuple[Any, ...]) -> str:
    kinds = {type(item) for item in items[:MAX_ARRAY_ITEMS]}
    if len(kinds) != 1:
        return "mixed"
    kind = kinds.pop()
    if kind in (bool, int, float, str):
        return kind.__name__
    return "object"


def message_text(msg: object) -> str:
    """``msg`` summarised (``summarise``) as JSON text of at most ``MAX_MESSAGE_CHARS``.

    Longer text is cut and ends with ``...<cut: N chars>`` (no longer valid JSON).
    """
    text = json.dumps(summarise(msg), ensure_ascii=False, default=repr)
    if len(text) > MAX_MESSAGE_CHARS:
        return f"{text[:MAX_MESSAGE_CHARS]}...<cut: {len(text)} chars>"
    return text


def encode_image(msg: Mapping[str, object], message_type: str) -> tuple[bytes, str]:
    """An image message as ``(bytes, MIME type)``: PNG for ``Image``, JPEG or PNG else.

    A ``sensor_msgs/Image`` is converted to 8-bit RGB (``image_to_display``, the
    video server's conversion) and encoded as PNG; a ``CompressedImage`` in JPEG or
    PNG is passed on as it is unless over ``MAX_IMAGE_BYTES`` or
    ``MAX_IMAGE_SIDE``, then re-encoded as JPEG; one that would decode to more
    than ``MAX_DECODE_PIXELS`` pixels is refused from its header
    (``rwt_graph.media.compressed``). Images are scaled down to ``MAX_IMAGE_SIDE``
    pixels on their longer side. Seconds of CPU for a large image: callers run it
    in an image thread (``rwt_graph.media.threads.in_image_thread``), never on the
    event loop.

    Args:
        msg: the message as the client decoded it: ``data`` as bytes, or as the
            base64 text of rosbridge's JSON encoding.
        message_type: ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``
            (either dialect).

    Raises:
        ImageError: an unknown encoding or format, or data that does not hold
            the image the header describes.
    """
    data = _bytes(msg.get("data"))
    if message_type.endswith("CompressedImage"):
        content_type = compressed_content_type(str(msg.get("format", "")))
        if content_type is None:
            raise ImageError(f"unknown compressed image format {msg.get('format')!r}")
        image = open_compressed(data, fit=MAX_IMAGE_SIDE)  # the header; a JPEG drafted
        with image:
            if len(data) <= MAX_IMAGE_BYTES and max(image.size) <= MAX_IMAGE_SIDE:
                return data, content_type
            try:
                return _encode(image.convert("RGB"), "JPEG"), "image/jpeg"
            except (OSError, ValueError, SyntaxError) as exc:  # data cut short, corrupt
                raise ImageError(f"the compressed image cannot be read: {exc}") from None
    pixels = image_to_display({**msg, "data": data})
    return _encode(Image.fromarray(pixels), "PNG"), "image/png"


def _encode(image: Image.Image, image_format: str) -> bytes:
    """``image`` scaled down to ``MAX_IMAGE_SIDE`` and encoded."""
    image.thumbnail((MAX_IMAGE_SIDE, MAX_IMAGE_SIDE))  # keeps the aspect ratio, never enlarges
    out = io.BytesIO()
    if image_format == "JPEG":
        image.save(out, "JPEG", quality=_JPEG_QUALITY)
    else:
        image.save(out, "PNG")
    return out.getvalue()


def _bytes(data: object) -> bytes:
    """Image data as bytes: rosbridge's JSON sends ``uint8[]`` as base64 text."""
    if isinstance(data, bytes | bytearray | memoryview):
        return bytes(data)
    if isinstance(data, str):
        try:
            return pybase64.b64decode(data, validate=True)
        except ValueError:
            raise ImageError("image data is neither bytes nor base64 text") from None
    if isinstance(data, list) and all(isinstance(item, int) for item in data):
        try:
            return bytes(data)
        except ValueError:
            raise ImageError("image data has values outside 0-255") from None
    raise ImageError("the message has no image data")
