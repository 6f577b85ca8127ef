"""A ROS 1 bag writer whose file header is laid out as real rosbag lays it out.

The ROS 1 bag format 2.0 (wiki.ros.org/Bags/Format/2.0) pads the bag header
record so that it can be rewritten in place when the bag closes. Real rosbag
(``bag.py``: ``_write_file_header_record`` writes the record with
``padded_size=_FILE_HEADER_LENGTH``) makes the record's header fields plus the
padding 4096 bytes, so with the record's two 4-byte length fields and the
13-byte ``#ROSBAG V2.0`` line the first chunk starts at byte 4117. rosbags
(0.11) counts the two length fields inside the 4096, so its first chunk starts
at 4109. rosbag's readers follow the lengths and read both, but ``rosbag
reindex`` and ``rosbag.Bag(path, 'a')`` rewrite the header with their own
layout: 8 bytes longer, over the start of the first chunk (reindex then finds
no chunk and leaves the bag unindexed; append leaves it unreadable).

``Ros1Writer`` is rosbags' writer with the header written as rosbag writes it:
when the bag opens (index position 0, as a killed recording leaves it) and
again after rosbags' own rewrite at close. Its ``checkpoint`` writes the open
chunk to the file, so that a killed recorder leaves every message up to the
last checkpoint on disk, in chunks that ``rosbag reindex`` and ``rwt bag
reindex`` index again.
"""

from __future__ import annotations

import struct
from typing import BinaryIO

from rosbags.rosbag1 import Writer
from rosbags.rosbag1.reader import RecordType
from rosbags.rosbag1.writer import Header

from .formats import ROS1_MAGIC as MAGIC

__all__ = [
    "FIRST_RECORD",
    "HEADER_POS",
    "MAGIC",
    "Ros1Writer",
    "record_fields",
    "write_file_header",
]

HEADER_POS = len(MAGIC)
"""Where the bag header record starts."""
_PADDED = 4096  # rosbag's _FILE_HEADER_LENGTH: header fields plus padding
FIRST_RECORD = HEADER_POS + 4 + _PADDED + 4
"""Where real rosbag's first record after the bag header starts (4117)."""


def write_file_header(file: BinaryIO, index_pos: int, conn_count: int, chunk_count: int) -> None:
    """Write the bag header record at ``HEADER_POS``, padded as real rosbag pads it.

    ``index_pos`` is the byte offset of the index (0: unindexed), the counts
    are the bag's connection and chunk records. The file is left positioned
    at ``FIRST_RECORD``.
    """
    header = Header()
    header.set_uint64("index_pos", index_pos)
    header.set_uint32("conn_count", conn_count)
    header.set_uint32("chunk_count", chunk_count)
    fields = bytearray()
    fields += struct.pack("<L", 4) + b"op=" + bytes([RecordType.BAGHEADER])
    for key, value in header.items():
        item = key.encode() + b"=" + value
        fields += struct.pack("<L", len(item)) + item
    pad = _PADDED - len(fields)
    file.seek(HEADER_POS)
    file.write(struct.pack("<L", len(fields)) + fields + struct.pack("<L", pad) + b" " * pad)


class Ros1Writer(Writer):
    """rosbags' ROS 1 writer, with real rosbag's bag header layout (see the module)."""

    def open(self) -> None:
        """Create the bag and write an unindexed header.

        Raises:
            rosbags.rosbag1.WriterError: the path exists.
        """
        super().open()
        assert self.bio is not None
        write_file_header(self.bio, 0, 0, 0)

    def checkpoint(self, *, full: bool = True) -> None:
        """Write the open chunk (with its index records) and hand it to the kernel.

        ``full`` is accepted for the rosbag2 writers' signature: a ROS 1 chunk is
        always written whole.

        Raises:
            OSError: the disk refused the data.
        """
        assert self.bio is not None
        self.write_chunk(self.chunks[-1])  # an empty chunk is not written
        self.bio.flush()

    def close(self) -> None:
        """Write the open chunk, the index and the header (rosbag's layout)."""
        path = self.path
        super().close()  # its header is 8 bytes short, followed by our padding's spaces
        with path.open("r+b") as file:
            file.seek(HEADER_POS)
            (size,) = struct.unpack("<L", file.read(4))
            fields = record_fields(file.read(size))
            index_pos, conns, chunks = (
                struct.unpack("<Q", fields[b"index_pos"])[0],
                struct.unpack("<L", fields[b"conn_count"])[0],
                struct.unpack("<L", fields[b"chunk_count"])[0],
            )
            write_file_header(file, index_pos, conns, chunks)


def record_fields(data: bytes) -> dict[bytes, bytes]:
    """The ``name=value`` fields of a record header (its bytes after the length).

    A field cut short by the end of ``data`` is left out.
    """
    found = {}
    pos = 0
    while pos + 4 <= len(data):
        (size,) = struct.unpack_from("<L", data, pos)
        if pos + 4 + size > len(data):
            break
        name, _, value = data[pos + 4 : pos + 4 + size].partition(b"=")
        found[name] = value
        pos += 4 + size
    return found
