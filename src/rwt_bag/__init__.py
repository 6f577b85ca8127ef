"""Record and replay: bags in, bags out, without ROS (docs/record-replay.md).

``Recorder(graph, path, topics=...)`` records topics of a graph into a ROS 2
bag (MCAP or sqlite3) or a ROS 1 bag; ``Player(graph, path, ...)`` publishes a
bag's topics into a graph with their original timing; ``bag_info`` summarizes a
bag. All file work goes through rosbags; the modules load with the first use of
a name (PEP 562), so `rwt serve` without --record or --play stays small.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from .errors import BagError
from .formats import BagFormat, ChunkCompression, Compression, SplitPolicy
from .selection import TopicSelection

if TYPE_CHECKING:
    from .controls import serve_controls
    from .info import BagInfo, bag_info
    from .player import Player, PlayStats
    from .recorder import Recorder, RecordStats

__all__ = [
    "BagError",
    "BagFormat",
    "BagInfo",
    "ChunkCompression",
    "Compression",
    "PlayStats",
    "Player",
    "RecordStats",
    "Recorder",
    "SplitPolicy",
    "TopicSelection",
    "bag_info",
    "serve_controls",
]

_HOMES = {
    "BagInfo": "info",
    "bag_info": "info",
    "PlayStats": "player",
    "Player": "player",
    "RecordStats": "recorder",
    "Recorder": "recorder",
    "serve_controls": "controls",
}


def __getattr__(name: str) -> object:
    """Load a public name from its module on first use.

    Raises:
        AttributeError: ``name`` is not part of the package's API.
    """
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'rwt_bag' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value
    return value
