"""Hostile bags, made small on purpose: decompression bombs, truncated files, bad names.

Each builder writes a file that is tiny on disk and hostile when read: an MCAP
whose zstd or lz4 chunk of zeros expands to gigabytes (with an honest or a
lying declared size, one or many chunks, no summary so readers must scan), a
ROS 1 bag whose bz2 chunk does the same, a truncated copy of a good bag, and
bags with topic names a client's ``advertise`` is refused. Used by the bag
tests and the fuzz grammar (tests/fuzz).
"""

from __future__ import annotations

import sqlite3
import struct
from typing import IO, TYPE_CHECKING
from unittest import mock

import lz4.frame  # type: ignore[import-untyped]
import yaml
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.rosbag2 import writer as rosbag2_writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.storage_mcap import zstd  # type: ignore[attr-defined]
from rosbags.typesys import Stores, get_typestore

if TYPE_CHECKING:
    from pathlib import Path

MAGIC = b"\x89MCAP0\r\n"
MIB = 1 << 20
BAD_NAMES = ("/x y", "/../..", "/a\u202eb", "/" + "n" * 5000)


def _record(op: int, body: bytes) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(body)) + body


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def zeros(size: int, compression: str = "zstd") -> bytes:
    """``size`` zero bytes compressed (made a MiB at a time: no ``size`` bytes in memory)."""
    if compression == "bz2":
        return _bz2_zeros(size)
    block = bytes(MIB)
    if compression == "lz4":
        out = lz4.frame.LZ4FrameCompressor()
        parts = [out.begin()]
    else:
        out = zstd.ZstdCompressor()
        parts = []
    left = size
    while left:
        step = min(left, MIB)
        parts.append(out.compress(block[:step]))
        left -= step
    parts.append(out.flush())
    return b"".join(parts)


_BZ2_UNIT = 16 * MIB
_BZ2_END = 0x177245385090  # the 48-bit magic of a bz2 stream's end (bzip2's format)


def _bz2_zeros(size: int) -> bytes:
    """``size`` zeros as one bz2 stream, its blocks copied rather than compressed.

    bzip2 takes about 1 s per 100 MiB even of zeros; a stream is a header, blocks
    (each with its own CRC, bit-aligned) and an end mark with a CRC combined from
    the blocks'. So one block of ``_BZ2_UNIT`` zeros is compressed once and
    repeated, and the rest is a last block: any bz2 decompressor reads the whole.
    """
    import bz2  # noqa: PLC0415

    if size == 0:
        return bz2.compress(b"", 9)  # a stream without blocks
    whole, rest = divmod(size, _BZ2_UNIT)
    blocks = [_bz2_block(bz2.compress(bytes(_BZ2_UNIT), 9))] * whole
    if rest or not blocks:
        blocks.append(_bz2_block(bz2.compress(bytes(rest), 9)))
    bits, count, combined = 0, 0, 0
    for block, length, crc in blocks:
        bits, count = (bits << length) | block, count + length
        combined = (((combined << 1) | (combined >> 31)) & 0xFFFFFFFF) ^ crc
    bits, count = (bits << 80) | (_BZ2_END << 32) | combined, count + 80
    pad = -count % 8
    return b"BZh9" + ((bits << pad).to_bytes((count + pad) // 8, "big"))


def _bz2_block(stream: bytes) -> tuple[int, int, int]:
    """The one block of a bz2 ``stream`` (``BZh9``): its bits, their count, its CRC."""
    assert stream.startswith(b"BZh9")
    body = int.from_bytes(stream[4:], "big")
    total = (len(stream) - 4) * 8
    for pad in range(8):  # the stream ends with the end mark, its CRC and 0-7 zero bits
        end = total - pad - 80
        if (body >> (pad + 32)) & ((1 << 48) - 1) == _BZ2_END:
            crc = (body >> pad) & 0xFFFFFFFF
            block_crc = (body >> (total - 48 - 32)) & 0xFFFFFFFF
            if crc == block_crc:  # one block: the combined CRC is its own
                return body >> (total - end), end, crc
    raise AssertionError("not a one-block bz2 stream")


def mcap_bomb(
    path: Path,
    *,
    size: int = 2048 * MIB,
    declared: int | None = None,
    chunks: int = 1,
    compression: str = "zstd",
) -> Path:
    """A summary-less MCAP of ``chunks`` chunks of ``size`` zeros each (declaring ``declared``).

    A reader finds no summary and scans, decompressing every chunk: zeros parse as
    empty records, 9 bytes each. Returns ``path`` (a bare ``.mcap`` file).
    """
    payload = zeros(size, compression)
    body = (
        struct.pack("<QQQI", 0, 1, size if declared is None else declared, 0)
        + _string(compression)
        + struct.pack("<Q", len(payload))
        + payload
    )
    chunk = _record(0x06, body)
    data = MAGIC + _record(0x01, _string("ros2") + _string("hostile"))
    data += chunk * chunks
    data += _record(0x0F, b"")  # data end
    data += _record(0x02, struct.pack("<QQI", 0, 0, 0)) + MAGIC
    path.write_bytes(data)
    return path


_FRAME_MAGIC = {"bz2": b"BZh", "lz4": b"\x04\x22\x4d\x18"}


def ros1_bomb(path: Path, *, size: int = 2048 * MIB, compression: str = "bz2") -> Path:
    """A ROS 1 bag whose one chunk (a /chatter String) is replaced by ``size`` zeros (bz2, lz4).

    Written by rosbags, then the chunk's payload is replaced by the bomb with its
    record sizes kept consistent; the index still points into the chunk.
    """
    store = get_typestore(Stores.ROS1_NOETIC)
    writer = Ros1Writer(path)
    writer.set_compression(Ros1Writer.CompressionFormat[compression.upper()])
    with writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hi")
        writer.write(conn, 1, store.serialize_ros1(msg, "std_msgs/msg/String"))
    data = bytearray(path.read_bytes())
    # the chunk record: header (with compression=bz2), then uint32 length and data
    at = data.index(b"compression=" + compression.encode())
    start = data.index(_FRAME_MAGIC[compression], at)
    length = struct.unpack_from("<I", data, start - 4)[0]
    payload = zeros(size, compression)
    data[start - 4 : start + length] = struct.pack("<I", len(payload)) + payload
    shift = len(payload) - length
    _shift_ros1_index(data, start, shift)
    path.write_bytes(bytes(data))
    return path


def _shift_ros1_index(data: bytearray, after: int, shift: int) -> None:
    """Move the bag header's ``index_pos`` (past ``after``) by ``shift`` bytes."""
    key = b"index_pos="
    at = data.index(key) + len(key)
    (pos,) = struct.unpack_from("<Q", data, at)
    if pos > after:
        struct.pack_into("<Q", data, at, pos + shift)


def sqlite3_bomb(path: Path, *, size: int = 2048 * MIB, mode: str = "message") -> Path:
    """A zstd-compressed rosbag2 sqlite3 bag holding ``size`` zeros.

    ``mode`` ``message``: its one row is the bomb; ``file``: the whole storage
    file is (rosbag2 decompresses it to a temporary file before reading).
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    msgtype = "std_msgs/msg/String"
    writer = Ros2Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3)
    compression = CompressionMode.MESSAGE if mode == "message" else CompressionMode.FILE
    writer.set_compression(compression, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection("/chatter", msgtype, typestore=store)
        raw = store.serialize_cdr(store.types[msgtype](data="hi"), msgtype)
        writer.write(conn, 10**9, raw)
    if mode == "file":
        (packed,) = path.glob("*.zstd")
        packed.write_bytes(zeros(size))
        return path
    (db,) = path.glob("*.db3")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET data = ?", (zeros(size),))
    return path


def truncated(source: Path, path: Path, keep: float = 0.5) -> Path:
    """The first ``keep`` of a bag file's bytes."""
    data = source.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    return path


def bad_names(
    path: Path, fmt: str = "mcap", names: tuple[str, ...] = BAD_NAMES, *, chatter: bool = True
) -> Path:
    """A bag with a good ``/chatter`` (unless not ``chatter``) and a String topic per name.

    Each topic has one message ("hostile"); ``fmt`` is mcap, sqlite3 or ros1
    (then ``path`` gets .bag).
    """
    ros1 = fmt == "ros1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_JAZZY)
    msgtype = "std_msgs/msg/String"
    msg = store.types[msgtype](data="hostile")
    topics = ("/chatter", *names) if chatter else names
    if ros1:
        path = path.with_suffix(".bag")
        with Ros1Writer(path) as writer:
            for i, name in enumerate(topics):
                conn = writer.add_connection(name, msgtype, typestore=store)
                writer.write(conn, 10**9 + i, store.serialize_ros1(msg, msgtype))
        return path
    plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
    with Ros2Writer(path, version=9, storage_plugin=plugin) as writer:
        for i, name in enumerate(topics):
            conn = writer.add_connection(name, msgtype, typestore=store)
            writer.write(conn, 10**9 + i, store.serialize_cdr(msg, msgtype))
    return path


def escaped_names(path: Path, fmt: str, escapes: tuple[str, ...], *, chatter: bool = True) -> Path:
    """A ROS 2 bag whose ``metadata.yaml`` names its topics with YAML escapes.

    rosbags takes a ROS 2 bag's topic names from ``metadata.yaml``, and YAML's
    double-quoted ``"\\ud800"`` is a lone surrogate: a name no UTF-8 writer
    could put in the storage file. ``escapes`` are the names as written in the
    YAML (``/\\ud800x``); ``fmt`` is mcap or sqlite3.
    """
    placeholders = tuple(f"/escaped{i}" for i in range(len(escapes)))
    bag = bad_names(path, fmt, placeholders, chatter=chatter)
    meta = bag / "metadata.yaml"
    text = meta.read_text()
    for placeholder, escape in zip(placeholders, escapes, strict=True):
        text = text.replace(f"name: {placeholder}\n", f'name: "{escape}"\n')
    meta.write_text(text)
    return bag


def undecodable_name(path: Path, fmt: str) -> Path:
    """A bag (mcap, sqlite3 or ros1) with ``/chatter`` and a topic whose name is not UTF-8.

    The name's bytes are an encoded surrogate (``ED A0 80``), written over a
    placeholder of the same length in every file of the bag.
    """
    placeholder, hostile = b"/utf8x", b"/\xed\xa0\x80xy"
    bag = bad_names(path, fmt, (placeholder.decode(),))
    for file in [bag] if bag.is_file() else sorted(bag.iterdir()):
        file.write_bytes(file.read_bytes().replace(placeholder, hostile))
    return bag


def many_topics(path: Path, count: int) -> Path:
    """An MCAP bag with ``count`` String topics of one message each (huge counts)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    msgtype = "std_msgs/msg/String"
    raw = store.serialize_cdr(store.types[msgtype](data="x"), msgtype)
    msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
    digest = store.hash_rihs01(msgtype)
    with (
        mock.patch.object(rosbag2_writer, "YAML", _LibYaml),
        Ros2Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer,
    ):
        for i in range(count):
            conn = writer.add_connection(f"/t{i}", msgtype, msgdef=msgdef, rihs01=digest)
            writer.write(conn, 10**9 + i, raw)
    return path


class _LibYaml:
    """What rosbags' writer asks of ruamel's ``YAML(typ="safe")``, done by libyaml.

    The same document (``metadata.yaml`` and the MCAP's copy of it), written in
    milliseconds: ruamel's pure-Python emitter takes seconds per thousand topics.
    """

    def __init__(self, typ: str = "safe") -> None:
        assert typ == "safe"
        self.default_flow_style = False

    def dump(self, data: object, stream: IO[str]) -> None:
        yaml.dump(data, stream, Dumper=yaml.CSafeDumper, default_flow_style=False)


__all__ = [
    "BAD_NAMES",
    "bad_names",
    "escaped_names",
    "many_topics",
    "mcap_bomb",
    "ros1_bomb",
    "sqlite3_bomb",
    "truncated",
    "undecodable_name",
    "zeros",
]
