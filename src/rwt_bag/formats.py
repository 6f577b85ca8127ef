"""The bag formats, split policy and chunk compression: the options' values, without rosbags."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING

from .errors import BagError

if TYPE_CHECKING:
    from pathlib import Path

ROS1_MAGIC = b"#ROSBAG V2.0\n"
"""The first line of every ROS 1 bag file (the ROS 1 bag format 2.0)."""


def is_ros1_bag(path: Path) -> bool:
    """Whether ``path`` is a file that starts as a ROS 1 bag does (``ROS1_MAGIC``).

    False for a folder (a ROS 2 bag), a missing path or an unreadable file.
    """
    try:
        with path.open("rb") as file:
            return file.read(len(ROS1_MAGIC)) == ROS1_MAGIC
    except OSError:
        return False


__all__ = ["BagFormat", "ChunkCompression", "Compression", "SplitPolicy"]


class BagFormat(StrEnum):
    """The bag formats ``rwt record`` writes."""

    MCAP = "mcap"
    SQLITE3 = "sqlite3"
    ROS1 = "ros1"


@dataclass(frozen=True)
class SplitPolicy:
    """When to start a new bag file; None: never.

    Attributes:
        max_bytes: serialized message bytes per file.
        max_seconds: receive-time span per file.
    """

    max_bytes: int | None = None
    max_seconds: float | None = None


class ChunkCompression(StrEnum):
    """How the chunks of an MCAP file are compressed (the MCAP spec's ``compression`` field)."""

    NONE = "none"
    ZSTD = "zstd"
    LZ4 = "lz4"


#: The levels each algorithm takes (zstd's negative ones are its fast modes;
#: LZ4 frame: 0-2 fast, 3-16 high compression) and the one used when none is given.
LEVELS = {
    ChunkCompression.ZSTD: (range(-7, 23), 3),
    ChunkCompression.LZ4: (range(17), 0),
}


@dataclass(frozen=True)
class Compression:
    """The chunk compression of an MCAP bag.

    Attributes:
        algorithm: none, zstd or lz4.
        level: the algorithm's level (zstd -7 to 22, lz4 0 to 16); None: its default.

    Raises:
        BagError: a level outside the algorithm's range, or a level without one.
    """

    algorithm: ChunkCompression = ChunkCompression.NONE
    level: int | None = None

    def __post_init__(self) -> None:
        if self.level is None:
            return
        if self.algorithm is ChunkCompression.NONE:
            raise BagError("a compression level needs a compression (zstd or lz4)")
        levels, _ = LEVELS[self.algorithm]
        if self.level not in levels:
            raise BagError(
                f"{self.algorithm.value} compression levels are {levels.start} to "
                f"{levels.stop - 1}, not {self.level}"
            )

    def check_format(self, fmt: BagFormat) -> Compression:
        """This compression, if a bag of ``fmt`` takes it (MCAP; any bag takes none).

        Raises:
            BagError: a chunk compression for a sqlite3 or ROS 1 bag.
        """
        if self.algorithm is not ChunkCompression.NONE and fmt is not BagFormat.MCAP:
            raise BagError(
                f"chunk compression ({self.algorithm.value}) is for MCAP bags, not {fmt.value}"
            )
        return self

    @property
    def effective_level(self) -> int:
        """The level used: the one given or the algorithm's default (0 without compression)."""
        if self.algorithm is ChunkCompression.NONE:
            return 0
        return self.level if self.level is not None else LEVELS[self.algorithm][1]
