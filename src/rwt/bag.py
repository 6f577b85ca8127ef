"""Recording topics into bags and playing bags to clients (docs/record-replay.md).

ROS 1 and ROS 2 bags (MCAP, sqlite3) through rosbags, which loads with the
first of these names used.

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_bag import (
        BagError,
        BagFormat,
        BagInfo,
        Player,
        PlayStats,
        Recorder,
        RecordStats,
        SplitPolicy,
        bag_info,
        serve_controls,
    )
    from rwt_bag.formats import ChunkCompression, Compression
    from rwt_bag.info import TopicSummary
    from rwt_bag.selection import TopicSelection
    from rwt_graph.playback import PlaybackStatus

__all__ = [
    "BagError",
    "BagFormat",
    "BagInfo",
    "ChunkCompression",
    "Compression",
    "PlayStats",
    "PlaybackStatus",
    "Player",
    "RecordStats",
    "Recorder",
    "SplitPolicy",
    "TopicSelection",
    "TopicSummary",
    "bag_info",
    "serve_controls",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
