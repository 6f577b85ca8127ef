"""``rwt bag reindex``: make a bag cut short (its recorder killed) readable again.

A ROS 1 bag gets a new index (``reindex_ros1``), as ``rosbag reindex`` gives
it; a ROS 2 bag folder gets a complete MCAP summary and footer, or sqlite3
database, and a new ``metadata.yaml`` (``reindex_ros2``), as ``ros2 bag
reindex`` regenerates it. The original is kept next to the result, as rosbag
keeps it: ``NAME.orig.bag`` for a ROS 1 bag, the folder ``NAME.orig`` for a
ROS 2 bag. A backup already there is never overwritten (the reindex is
refused). The new bag is written under a temporary name first, so a reindex
that fails leaves the original as it was.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from .errors import BagError
from .reindex_ros1 import Reindexed, reindex_ros1
from .reindex_ros2 import reindex_ros2
from .ros1 import MAGIC

__all__ = ["Reindexed", "backup_path", "reindex"]


def backup_path(path: Path) -> Path:
    """Where ``reindex`` keeps the original: ``run.orig.bag`` for ``run.bag``, else ``run.orig``."""
    return path.with_name(f"{path.stem}.orig{path.suffix}")


def reindex(path: Path) -> Reindexed:
    """Rebuild the index of the bag at ``path`` in place, keeping the original.

    Raises:
        BagError: ``path`` is missing or not a bag, its backup exists already,
            or a chunk decompresses past the limits (docs/limits.md).
        OSError: reading or writing failed.
    """
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path} does not exist")
    if path.is_dir():
        rebuild = reindex_ros2
    elif _starts_with(path, MAGIC):
        rebuild = reindex_ros1
    else:
        raise BagError(f"{path} is not a bag (a ROS 1 .bag file, or a ROS 2 bag folder)")
    backup = backup_path(path)
    if backup.exists():
        raise BagError(f"{backup} exists already: move it away to reindex {path} again")
    # the new bag under its own name (rosbag2 names its files after the folder)
    # in a hidden folder next to it, the same file system, so it moves in at once
    work = path.with_name(f".{path.name}.reindex")
    shutil.rmtree(work, ignore_errors=True)  # left by a reindex that was itself killed
    work.mkdir()
    try:
        done = rebuild(path, work / path.name)
        path.rename(backup)
        (work / path.name).rename(path)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return done


def _starts_with(path: Path, magic: bytes) -> bool:
    with path.open("rb") as file:
        return file.read(len(magic)) == magic
