"""``rwt bag info`` names the storage of a bare .mcap and keeps nanoseconds."""

from __future__ import annotations

from pathlib import Path

from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

from rwt_bag.info import bag_info

FIRST_NS = 1_700_000_000_123_456_789
LAST_NS = 1_700_000_001_987_654_321


def write(path: Path, plugin: StoragePlugin) -> Path:
    store = get_typestore(Stores.ROS2_HUMBLE)
    String = store.types["std_msgs/msg/String"]
    with Ros2Writer(path, version=9, storage_plugin=plugin) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        for ns in (FIRST_NS, LAST_NS):
            writer.write(conn, ns, store.serialize_cdr(String(data="x"), "std_msgs/msg/String"))
    return path


def test_a_bare_mcap_file_is_mcap_and_times_keep_their_nanoseconds(tmp_path: Path) -> None:
    folder = write(tmp_path / "bag", StoragePlugin.MCAP)
    bare = next(folder.glob("*.mcap"))
    info = bag_info(bare)
    assert info.storage == "mcap"
    assert (info.start_ns, info.end_ns) == (FIRST_NS, LAST_NS)
    text = info.format()
    assert "Storage id:        mcap" in text
    assert "1700000000.123456789" in text
    assert "1700000001.987654321" in text
    assert "2023-11-14T22:13:20.123456789" in text


def test_folders_name_their_storage(tmp_path: Path) -> None:
    assert bag_info(write(tmp_path / "m", StoragePlugin.MCAP)).storage == "mcap"
    assert bag_info(write(tmp_path / "s", StoragePlugin.SQLITE3)).storage == "sqlite3"
