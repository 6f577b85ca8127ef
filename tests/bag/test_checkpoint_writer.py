"""The MCAP checkpoint writes its tail from rosbags' buffers, and the bag reads back whole.

``rwt_bag.mcap`` writes a checkpoint's tail (chunk, indexes, summary, footer)
with ``os.pwritev`` in batches of at most ``_IOV_MAX`` buffers, or with one
joined ``write`` where ``pwritev`` is missing. Each way, a bag read at a
checkpoint (still open, as after a kill) and after closing holds every message.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin

from rwt_bag import mcap
from rwt_bag.mcap import CheckpointWriter
from rwt_graph.types import Dialect, TypeRegistry


def _payloads(count: int) -> list[bytes]:
    """CDR of std_msgs/String: small ones and 200 KB ones (large tail pieces)."""
    store = TypeRegistry(Dialect.ROS2).typestore()
    cls = store.types["std_msgs/msg/String"]
    texts = [f"{i}:" + ("x" * (200_000 if i % 3 == 0 else 10)) for i in range(count)]
    return [bytes(store.serialize_cdr(cls(data=t), "std_msgs/msg/String")) for t in texts]


def _read(path: Path) -> list[bytes]:
    with AnyReader([path]) as reader:
        return [bytes(raw) for _, _, raw in reader.messages()]


@pytest.mark.parametrize(("pwritev", "iov_max"), [(True, 1024), (True, 2), (False, 1024)])
def test_checkpoints_and_close_keep_every_message(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, pwritev: bool, iov_max: int
) -> None:
    monkeypatch.setattr(mcap, "_HAVE_PWRITEV", pwritev)
    monkeypatch.setattr(mcap, "_IOV_MAX", iov_max)
    store = TypeRegistry(Dialect.ROS2).typestore()
    payloads = _payloads(60)
    path = tmp_path / "bag"
    writer = CheckpointWriter(path, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn = writer.add_connection("/t", "std_msgs/msg/String", typestore=store)
    for i, raw in enumerate(payloads):
        writer.write(conn, 1_000 + i, raw)
        if i % 20 == 19:
            writer.checkpoint(full=i == 19)
            assert _read(path) == payloads[: i + 1]  # readable mid-run, as after a kill
    writer.write(conn, 5_000, payloads[0])
    writer.close()
    assert _read(path) == [*payloads, payloads[0]]
