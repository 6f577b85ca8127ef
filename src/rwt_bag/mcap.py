"""A rosbag2 MCAP writer that keeps the bag readable while it grows (checkpoints).

rosbags' MCAP storage writes the summary and footer, and rosbag2's
``metadata.yaml``, only when the bag is closed, so a recorder killed mid-run
would leave a file no reader opens. ``CheckpointWriter.checkpoint`` closes the
pending chunk and writes a complete summary, footer and ``metadata.yaml`` after
it; the next checkpoint writes its chunk over the previous summary. Between
checkpoints the chunk grows in memory, so a killed recorder leaves a bag that
reads up to its last checkpoint. The new tail (chunk, indexes, summary, footer)
is written with one system call (``os.pwritev`` of rosbags' own buffers, no
copy of the chunk first), which keeps the time in which a kill could leave a
torn tail as short as a copy into the page cache.

Chunks close when they reach ``CHUNK_BYTES`` or when the recorder asks for a
checkpoint (on a timer). The chunk is larger than rosbags' 1 MiB so that a
stream of large messages (1 MB images) is not checkpointed at every message:
each checkpoint also rewrites the summary and ``metadata.yaml``.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any, BinaryIO

import lz4.frame  # type: ignore[import-untyped]  # a rosbags dependency
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from .formats import ChunkCompression, Compression

try:  # Python 3.14's, else the backport rosbags depends on (as rosbags imports it)
    from compression import zstd  # type: ignore[import-not-found,unused-ignore]
except ImportError:
    from backports import zstd  # type: ignore[no-redef,unused-ignore]

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from rosbags.rosbag2.enums import CompressionMode

__all__ = ["CHUNK_BYTES", "CheckpointWriter"]

#: A chunk in memory is checkpointed from this size on (bounds the memory and the loss).
CHUNK_BYTES = 8 << 20
#: Pieces of a checkpoint's tail from this size on are written from rosbags' own buffers.
_LARGE = 64 * 1024
_HAVE_PWRITEV = hasattr(os, "pwritev")
_IOV_MAX = 1024  # the buffers one pwritev takes on Linux (IOV_MAX)


class _Tail:
    """A file stand-in that collects writes from ``offset`` on, for one ``write``.

    Large pieces (a closed chunk of images) are kept as the views rosbags hands
    over, not copied into one buffer; small ones are joined, so the tail is a
    few pieces for ``os.pwritev`` (one system call, B20).
    """

    def __init__(self, offset: int) -> None:
        self._offset = offset
        self._size = 0
        self.parts: list[bytes | bytearray | memoryview] = []
        self._small = bytearray()

    def write(self, data: bytes | memoryview) -> int:
        size = memoryview(data).nbytes
        if size < _LARGE:
            self._small += data
        else:
            if self._small:
                self.parts.append(self._small)
                self._small = bytearray()
            self.parts.append(data)
        self._size += size
        return size

    def tell(self) -> int:
        return self._offset + self._size

    def pieces(self) -> list[bytes | bytearray | memoryview]:
        """Everything written, in order."""
        return [*self.parts, self._small] if self._small else list(self.parts)

    def close(self) -> None:
        """The real file stays open: the bag goes on after the checkpoint."""


def _write_at(file: BinaryIO, pieces: list[bytes | bytearray | memoryview], offset: int) -> None:
    """Write ``pieces`` at ``offset`` of ``file`` (flushed), one system call where possible."""
    file.flush()
    if not _HAVE_PWRITEV:
        file.seek(offset)
        file.write(b"".join(pieces))
        file.flush()
        return
    fd = file.fileno()
    views = [memoryview(piece).cast("B") for piece in pieces]
    while views:
        written = os.pwritev(fd, views[:_IOV_MAX], offset)
        offset += written
        while views and written >= views[0].nbytes:  # drop what went out, keep a partial rest
            written -= views[0].nbytes
            views.pop(0)
        if written:
            views[0] = views[0][written:]


def _last_bytes(pieces: list[bytes | bytearray | memoryview], count: int) -> bytes:
    """The last ``count`` bytes of ``pieces`` joined (without joining the rest)."""
    out: list[bytes] = []
    for piece in reversed(pieces):
        if count <= 0:
            break
        view = memoryview(piece).cast("B")
        take = min(count, view.nbytes)
        out.append(bytes(view[view.nbytes - take :]))
        count -= take
    return b"".join(reversed(out))


class _McapStorage(McapWriter):
    """rosbags' MCAP storage whose chunks close only at a checkpoint."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        super().__init__(path, compression)
        self.in_checkpoint = False

    def close_chunk(self) -> None:
        """Close the chunk during a checkpoint only.

        rosbags closes a chunk from ``write`` past 1 MiB, straight into the file
        over the last summary; the checkpoint closes it instead, keeping the file
        readable.
        """
        if self.in_checkpoint:
            super().close_chunk()

    def pending_bytes(self) -> int:
        """Bytes of messages in the chunk not yet in the file."""
        return int(self.chunk.bio.tell())


def compressor(compression: Compression) -> tuple[str, Callable[[bytes], bytes]]:
    """The MCAP ``compression`` name and function of ``compression`` (``""``: none).

    zstd writes a zstd frame and lz4 an LZ4 frame, as the MCAP spec defines its
    two chunk compressions (what rosbags, the ``mcap`` readers and Foxglove read).
    """
    level = compression.effective_level
    if compression.algorithm is ChunkCompression.ZSTD:
        return "zstd", lambda data: zstd.compress(data, level)
    if compression.algorithm is ChunkCompression.LZ4:
        return "lz4", lambda data: bytes(lz4.frame.compress(data, compression_level=level))
    return "", _uncompressed


def _uncompressed(data: bytes) -> bytes:
    """No compression: the chunk as it is (no copy of its megabytes)."""
    return data


class _Sqlite3Storage(Sqlite3Writer):
    """rosbags' sqlite3 storage that can commit before it closes."""

    def pending_bytes(self) -> int:
        """Unknown for sqlite3; the recorder checkpoints it on its timer."""
        return 0


class CheckpointWriter(Writer):
    """A rosbag2 writer (MCAP or sqlite3) with ``checkpoint``.

    Args:
        path: the bag directory to create.
        storage_plugin: MCAP or sqlite3.
        compression: how MCAP chunks are compressed (sqlite3: ignored); None: not.
    """

    STORAGE_PLUGINS = {StoragePlugin.MCAP: _McapStorage, StoragePlugin.SQLITE3: _Sqlite3Storage}

    def __init__(
        self,
        path: Path,
        *,
        storage_plugin: StoragePlugin,
        compression: Compression | None = None,
    ) -> None:
        super().__init__(path, version=9, storage_plugin=storage_plugin)
        self._compression = compression or Compression()
        self._metadata: str | None = None  # the MCAP metadata record of the last full checkpoint
        self._summary = b""  # the file's tail after the last checkpoint's data (summary, footer)
        self._metadata_connections = -1

    def open(self) -> None:
        """Create the bag; MCAP chunks get the chosen compression.

        Raises:
            rosbags.rosbag2.WriterError: the bag exists.
        """
        super().open()
        storage: Any = self.storage
        if isinstance(storage, _McapStorage):
            # rosbags compresses with zstd (its own level) or not at all: ours replaces it
            storage.compression, storage.compressor = compressor(self._compression)

    @property
    def checkpoint_due(self) -> bool:
        """Whether the chunk in memory is full (MCAP, ``CHUNK_BYTES``)."""
        storage: Any = self.storage
        return storage is not None and storage.pending_bytes() >= CHUNK_BYTES

    def checkpoint(self, *, full: bool = True) -> None:
        """Make everything written so far readable: the file's tail and ``metadata.yaml``.

        Args:
            full: also rewrite ``metadata.yaml`` (counts and times; rosbags renders
                it as YAML, which costs milliseconds). A partial checkpoint (a full
                chunk between timed ones) writes the MCAP summary only, unless a
                topic was added since the last full one: readers take the topics
                from ``metadata.yaml``.

        Raises:
            OSError: the file cannot be written.
        """
        storage: Any = self.storage
        if isinstance(storage, _McapStorage):
            stale = len(self.connections) != self._metadata_connections
            self._checkpoint_mcap(storage, full=full or stale or self._metadata is None)
        elif storage is not None:
            storage.conn.commit()
            self._write_metadata(storage)
            self._publish_metadata()

    def _checkpoint_mcap(self, storage: _McapStorage, *, full: bool = True) -> None:
        file = storage.bio
        tail_start = file.tell()
        tail = _Tail(tail_start)
        storage.bio = tail  # type: ignore[assignment]  # a file stand-in
        storage.in_checkpoint = True
        try:
            if storage.pending_bytes():
                storage.close_chunk()
            data_end = tail.tell()
            if full:
                self._write_metadata(storage)  # the summary into ``tail``, metadata.yaml
            else:
                assert self._metadata is not None  # full is forced until there is one
                McapWriter.close(storage, self.version, self._metadata)  # the summary only
        finally:
            storage.bio = file
            storage.in_checkpoint = False
        try:
            _write_at(file, tail.pieces(), tail_start)
            file.truncate(tail.tell())
        except OSError:
            # the disk is full (or the file at its size limit): the new tail went out
            # in part, over the last summary. Put that summary back, so the bag reads
            # as it did at the last checkpoint (its metadata.yaml too), and let the
            # recorder stop.
            self._restore(file, tail_start)
            self._pending_metadata().unlink(missing_ok=True)
            raise
        if full:  # only now: metadata.yaml never counts what the file does not hold yet
            self._publish_metadata()
        file.seek(data_end)  # the next chunk goes over this summary
        # kept to restore it should the next checkpoint fail (a few KB: indexes, footer)
        self._summary = _last_bytes(tail.pieces(), tail.tell() - data_end)

    def _restore(self, file: BinaryIO, offset: int) -> None:
        """Cut ``file`` back to ``offset`` and write the last checkpoint's summary there."""
        try:
            file.truncate(offset)
            if self._summary:
                os.pwrite(file.fileno(), self._summary, offset)
        except OSError:  # not even that: the bag ends where the disk stopped it
            return

    def _pending_metadata(self) -> Path:
        """Where a checkpoint's ``metadata.yaml`` waits until the file holds what it counts."""
        return self.metapath.with_name(self.metapath.name + ".pending")

    def _publish_metadata(self) -> None:
        """Put the waiting ``metadata.yaml`` in place (a rename: a reader sees one or the other)."""
        self._pending_metadata().replace(self.metapath)

    def _write_metadata(self, storage: Any) -> None:
        """Run rosbags' ``close`` (storage tail, metadata.yaml) on a storage that stays open.

        The metadata goes to ``_pending_metadata`` (``_publish_metadata`` puts it in
        place): written first, a kill before the file's tail went out left a
        ``metadata.yaml`` counting messages the file did not hold.
        """
        real_close = storage.close

        def tail_only(version: int, metadata: str) -> None:
            if isinstance(storage, _McapStorage):
                real_close(version, metadata)  # writes into the ``_Tail``; the file stays open
                self._metadata = metadata
                self._metadata_connections = len(self.connections)

        storage.close = tail_only
        metapath = self.metapath
        self.metapath = self._pending_metadata()
        try:
            Writer.close(self)  # computes the metadata from the counts; sets storage None
        finally:
            del storage.close
            self.storage = storage
            self.metapath = metapath

    def close(self) -> None:
        """Write the final tail and metadata, and close the file."""
        storage: Any = self.storage
        if storage is None:
            return
        if isinstance(storage, _McapStorage):
            try:
                self._checkpoint_mcap(storage)
            finally:  # also when the disk refused the tail: the file is not left open
                storage.bio.close()
                self.storage = None
        else:
            Writer.close(self)
