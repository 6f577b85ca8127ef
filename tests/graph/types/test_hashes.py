"""RIHS01 type hashes (REP 2011) as rosidl computes them, against rosbags' own.

rosbags' ``Typestore.hash_rihs01`` is an independent implementation of the same
rule; rwt's differs only where rosidl reads a type otherwise (``char`` as
``uint8``, ``wstring`` as itself), so for types without those both must agree.
(tests/zenoh/test_wire.py checks a hash against rmw_zenoh's keys.)
"""

from __future__ import annotations

import pytest
from rosbags.typesys import Stores, get_typestore

from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.hashes import message_type_hash

# fixed arrays (float64[9], float64[36]), sequences of numbers, strings and nested types
TYPES = [
    "std_msgs/msg/String",
    "sensor_msgs/msg/JointState",
    "sensor_msgs/msg/CameraInfo",
    "sensor_msgs/msg/PointCloud2",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/OccupancyGrid",
    "diagnostic_msgs/msg/DiagnosticArray",
    "visualization_msgs/msg/MarkerArray",
]


@pytest.mark.parametrize("type_name", TYPES)
def test_the_hash_is_rosbags_rihs01_for_types_without_char_or_wstring(type_name: str) -> None:
    registry = TypeRegistry(Dialect.ROS2)
    store = get_typestore(Stores.LATEST)
    if type_name not in store.fielddefs:
        pytest.skip(f"rosbags' store has no {type_name}")
    assert message_type_hash(registry, type_name) == store.hash_rihs01(type_name)
