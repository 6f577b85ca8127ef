"""Without ``--dialect``, the bag says which graph it needs (docs/record-replay.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_bag.formats import BagFormat
from rwt_cli.bag_options import dialect_for
from rwt_graph.types import Dialect

from .bags import write_bag

if TYPE_CHECKING:
    from pathlib import Path


def test_a_ros1_bag_or_recording_asks_for_ros1_and_the_option_wins(tmp_path: Path) -> None:
    ros1 = write_bag(tmp_path / "old", "ros1")
    ros2 = write_bag(tmp_path / "new", "mcap")
    assert dialect_for(None, [ros1]) is Dialect.ROS1
    assert dialect_for(None, [ros2]) is Dialect.ROS2
    assert dialect_for(None, [tmp_path / "missing.bag"]) is Dialect.ROS2  # the reader says why
    assert dialect_for(None, (), BagFormat.ROS1) is Dialect.ROS1
    assert dialect_for(None) is Dialect.ROS2
    assert dialect_for(Dialect.ROS2, [ros1]) is Dialect.ROS2  # given: refused later, by the bag
