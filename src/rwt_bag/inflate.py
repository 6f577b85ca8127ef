"""Bounded decompression of bags: a small bag must not expand into gigabytes (docs/limits.md).

rosbags decompresses a whole chunk at once (MCAP zstd and lz4 chunks, ROS 1 bz2
and lz4 chunks, the zstd rows and files of compressed rosbag2 bags) with no cap:
a 33 KB MCAP holding a zstd chunk of zeros expands to gigabytes before a record
is looked at, and its 9-byte empty records then keep rosbags' record loop busy
for minutes. While a ``ReadBudget`` is active (every read rwt makes: opening,
``bag info``, each playback pass), each decompression

- refuses a chunk of more than ``MAX_CHUNK_BYTES`` decompressed, by its
  declared size before any work and by its output (it stops one byte past the
  cap), so a header that lies gets no further;
- charges its output to the read's budget, ``INFLATE_FLOOR_BYTES`` plus
  ``INFLATE_RATIO`` times the bag's bytes on disk: past it the read stops. That
  bounds both the memory and the work of a read by the size of the file.

Outside a budget rosbags' decompressors run as shipped, so other users of
rosbags in the same process see no change.
"""

from __future__ import annotations

import bz2
import contextvars
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, BinaryIO, TypeVar

import lz4.frame  # type: ignore[import-untyped]
import rosbags.rosbag1.reader as ros1_reader
import rosbags.rosbag2.reader as ros2_reader
import rosbags.rosbag2.storage_mcap as mcap_storage

from .errors import BagError

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence
    from pathlib import Path

__all__ = [
    "INFLATE_FLOOR_BYTES",
    "INFLATE_RATIO",
    "MAX_CHUNK_BYTES",
    "InflateError",
    "ReadBudget",
    "bag_bytes",
]

#: The largest chunk (or compressed row) decompressed, bytes. Writers close a
#: chunk near 1 MiB (rosbag2, ROS 1) or 8 MiB (rwt); only a single larger message
#: makes a larger one, and 256 MiB is past any message a server carries.
MAX_CHUNK_BYTES = 256 << 20
#: Bytes any read may decompress whatever the bag's size (a small bag of maps).
INFLATE_FLOOR_BYTES = 16 << 20
#: Beyond the floor, a read may decompress this many times the bag's bytes on
#: disk. Recorded data compresses 2 to 10 times; zeros compress 30 000 times.
INFLATE_RATIO = 100

_T = TypeVar("_T")
_ZSTD: Any = vars(mcap_storage)[
    "zstd"
]  # rosbags' own zstd module (compression.zstd or its backport)
_BUDGET: contextvars.ContextVar[ReadBudget | None] = contextvars.ContextVar(
    "rwt_bag_read_budget", default=None
)


class InflateError(BagError):
    """A chunk of a bag decompresses past a limit (a decompression bomb or a corrupt size)."""


def bag_bytes(paths: Sequence[Path]) -> int:
    """Bytes on disk of bag files or folders (the files directly in a folder)."""
    total = 0
    for path in paths:
        if path.is_dir():
            total += sum(f.stat().st_size for f in path.iterdir() if f.is_file())
        elif path.exists():
            total += path.stat().st_size
    return total


@dataclass
class ReadBudget:
    """Bytes one read of a bag may still decompress.

    Attributes:
        limit: bytes the read may decompress in all.
        bag: the bag's files, named in errors.
        used: bytes decompressed so far.
    """

    limit: int
    bag: str = "the bag"
    used: int = 0

    @classmethod
    def for_paths(cls, paths: Sequence[Path]) -> ReadBudget:
        """The budget of one read of ``paths``: floor plus ratio times their bytes."""
        names = ", ".join(str(p) for p in paths)
        return cls(INFLATE_FLOOR_BYTES + INFLATE_RATIO * bag_bytes(paths), names)

    @contextmanager
    def active(self) -> Iterator[ReadBudget]:
        """Apply the caps to every decompression in this context (thread)."""
        token = _BUDGET.set(self)
        try:
            yield self
        finally:
            _BUDGET.reset(token)

    def iterate(self, items: Iterator[_T]) -> Iterator[_T]:
        """``items`` with this budget active while each one is produced."""
        while True:
            token = _BUDGET.set(self)
            try:
                item = next(items)
            except StopIteration:
                return
            finally:
                _BUDGET.reset(token)
            yield item

    def allowance(self, declared: int | None) -> int:
        """The bytes the next chunk may decompress to.

        Raises:
            InflateError: its declared size is past the chunk cap or the budget.
        """
        left = self.limit - self.used
        if declared is not None:
            self._check(declared, left)
        return min(MAX_CHUNK_BYTES, left)

    def charge(self, size: int) -> None:
        """Count ``size`` decompressed bytes.

        Raises:
            InflateError: past the chunk cap or the budget.
        """
        self._check(size, self.limit - self.used)
        self.used += size

    def _check(self, size: int, left: int) -> None:
        if size > MAX_CHUNK_BYTES:
            raise InflateError(
                f"{self.bag}: a chunk decompresses to more than {MAX_CHUNK_BYTES >> 20} MiB "
                "(the limit of one chunk, docs/limits.md)"
            )
        if size > left:
            raise InflateError(
                f"{self.bag}: the bag decompresses to more than {self.limit >> 20} MiB "
                f"({INFLATE_RATIO} times its size on disk plus "
                f"{INFLATE_FLOOR_BYTES >> 20} MiB, docs/limits.md)"
            )


def _inflate(
    make: Callable[[], Any], data: bytes, declared: int | None, budget: ReadBudget
) -> bytes:
    """Decompress every frame (stream) of ``data``, at most the budget's allowance."""
    allowance = budget.allowance(declared)
    if declared is not None:
        allowance = min(allowance, declared)
    parts: list[bytes] = []
    size = 0
    rest: bytes = data
    while rest:
        decompressor = make()
        out = decompressor.decompress(rest, max_length=allowance - size + 1)
        parts.append(out)
        size += len(out)
        if size > allowance:  # more output is coming: stop here, one byte past the allowance
            if declared is not None and allowance == declared:
                raise InflateError(
                    f"{budget.bag}: a chunk decompresses past its declared {declared} bytes "
                    "(a corrupt or hostile chunk, docs/limits.md)"
                )
            budget.charge(size)  # raises: past the chunk cap or the read's budget
        if not decompressor.eof:
            raise InflateError(f"{budget.bag}: a compressed chunk is truncated")
        rest = decompressor.unused_data
    budget.charge(size)
    return parts[0] if len(parts) == 1 else b"".join(parts)  # one frame: no copy


def _bounded(
    original: Callable[..., bytes], make: Callable[[], Any], *, sized: bool
) -> Callable[..., bytes]:
    """A decompressor that applies the active budget, or is ``original`` outside one."""

    def decompress(data: bytes, *args: Any) -> bytes:
        budget = _BUDGET.get()
        if budget is None:
            return original(data, *args)
        declared = int(args[0]) if sized and args else None
        return _inflate(make, data, declared, budget)

    return decompress


class _BoundedStream:
    """A decompressing file whose reads are charged to the budget (rosbag2 file compression)."""

    def __init__(self, inner: Any, budget: ReadBudget) -> None:
        self._inner = inner
        self._budget = budget

    def read(self, size: int = -1) -> bytes:
        allowance = self._budget.allowance(None)
        want = allowance + 1 if size < 0 else min(size, allowance + 1)
        data: bytes = self._inner.read(want)
        self._budget.charge(len(data))
        return data

    def __enter__(self) -> _BoundedStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self._inner.close()


class _BoundedZstd:
    """rosbags.rosbag2.reader's ``zstd``: rows and files decompressed within the budget."""

    def decompress(self, data: bytes) -> bytes:
        budget = _BUDGET.get()
        if budget is None:
            return bytes(_ZSTD.decompress(data))
        return _inflate(_ZSTD.ZstdDecompressor, data, None, budget)

    def open(self, file: BinaryIO, mode: str = "rb") -> Any:
        stream = _ZSTD.open(file, mode)
        budget = _BUDGET.get()
        return stream if budget is None else _BoundedStream(stream, budget)

    def __getattr__(self, name: str) -> Any:
        return getattr(_ZSTD, name)


def _install() -> None:
    """Put the bounded decompressors into rosbags' tables (once; idempotent)."""
    if isinstance(vars(ros2_reader)["zstd"], _BoundedZstd):
        return
    table = mcap_storage.DECOMPRESSORS
    table["zstd"] = _bounded(table["zstd"], _ZSTD.ZstdDecompressor, sized=True)
    table["lz4"] = _bounded(table["lz4"], lz4.frame.LZ4FrameDecompressor, sized=True)
    ros1 = ros1_reader.decompressors
    ros1["bz2"] = _bounded(ros1["bz2"], bz2.BZ2Decompressor, sized=False)
    ros1["lz4"] = _bounded(ros1["lz4"], lz4.frame.LZ4FrameDecompressor, sized=False)
    vars(ros2_reader)["zstd"] = _BoundedZstd()  # the name its Reader looks up per call


_install()
