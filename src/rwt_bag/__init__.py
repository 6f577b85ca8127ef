"""Record and replay: bags in, bags out, without ROS (docs/record-replay.md).

``Recorder(graph, path, topics=...)`` records topics of a graph into a ROS 2
bag (MCAP or sqlite3) or a ROS 1 bag; ``Player(graph, path, ...)`` publishes a
bag's topics into a graph with their original timing; ``bag_info`` summarizes a
bag. All file work goes through rosbags.
"""

from __future__ import annotations

from .controls import serve_controls
from .errors import BagError
from .info import BagInfo, bag_info
from .player import Player, PlayStats
from .recorder import Recorder, RecordStats
from .writer import BagFormat, SplitPolicy

__all__ = [
    "BagError",
    "BagFormat",
    "BagInfo",
    "PlayStats",
    "Player",
    "RecordStats",
    "Recorder",
    "SplitPolicy",
    "bag_info",
    "serve_controls",
]
