"""``rwt bag reindex``: make a bag cut short (its recorder killed) readable again.

A ROS 1 bag gets a new index (``reindex_ros1``), as ``rosbag reindex`` gives
it. The original is kept next to it as ``NAME.orig.bag``, as rosbag keeps
it; a backup already there is not overwritten (the reindex is refused).
"""

from __future__ import annotations

from pathlib import Path

from .errors import BagError
from .reindex_ros1 import Reindexed, reindex_ros1
from .ros1 import MAGIC

__all__ = ["Reindexed", "backup_path", "reindex"]


def backup_path(path: Path) -> Path:
    """Where ``reindex`` keeps the original: ``run.bag`` -> ``run.orig.bag``."""
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
    if path.is_file() and _starts_with(path, MAGIC):
        backup = backup_path(path)
        if backup.exists():
            raise BagError(f"{backup} exists already: move it away to reindex {path} again")
        work = path.with_name(f".{path.name}.reindex")
        work.unlink(missing_ok=True)  # left by a reindex that was itself killed
        try:
            done = reindex_ros1(path, work)
            path.rename(backup)
            work.rename(path)
        finally:
            work.unlink(missing_ok=True)
        return done
    raise BagError(f"{path} is not a bag rwt can reindex (a ROS 1 .bag file)")


def _starts_with(path: Path, magic: bytes) -> bool:
    with path.open("rb") as file:
        return file.read(len(magic)) == magic
