"""The real Foxglove client in Node (tests/js/foxglove_extras.mjs) on `rwt serve --play`.

The bag (tests/bag/bags.py, written by rosbags) plays from a paused start; the
client resumes it and seeks through the /rwt/player services over rosbridge.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.bag.bags import CHATTER_GAP_S, T0, write_bag
from tests.integration.client_harness import ServerProcess

from . import extras

pytestmark = pytest.mark.node


@pytest.fixture(scope="module")
def player(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    tmp = tmp_path_factory.mktemp("foxplay")
    bag = write_bag(tmp / "bag", "mcap")
    process = ServerProcess(tmp, ("--play", str(bag), "--start-paused", "--no-tf"))
    try:
        yield process
    finally:
        process.stop()


def test_server_time_follows_the_bag_and_steps_on_a_seek(player: ServerProcess) -> None:
    got = extras.run("play", player.url, "/chatter", "4")
    assert "time" in got["capabilities"]
    gap = int(CHATTER_GAP_S * 1e9)
    first = T0 + 100_000_000
    assert got["messages"] == [
        {"logTime": str(first + i * gap), "data": f"chatter {i} ✓"} for i in range(4)
    ]
    times = [int(ns) for ns in got["times"]]
    assert times == sorted(times) and times[0] >= T0
    assert {first + i * gap for i in range(4)} <= set(times)  # each told before its message
    assert T0 <= int(got["stepBack"]) < first  # the seek to 0 shows as a step back
    assert got["afterSeek"] == {"logTime": str(first), "data": "chatter 0 ✓"}
