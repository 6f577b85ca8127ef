"""The bag formats and split policy: the options' values, without loading rosbags' writers."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

__all__ = ["BagFormat", "SplitPolicy"]


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
