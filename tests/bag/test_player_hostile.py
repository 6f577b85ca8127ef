"""Hostile calls of the player's services: refused with a reason, logged once per episode.

roslibpy calls ``/rwt/player/seek`` of ``rwt serve --play`` 100 times each with
NaN, infinity, a negative offset and one past the bag's end (JSON ``NaN`` and
``Infinity``, as Python's json writes them): every call gets ``success: false``
and a message naming the offset, the server logs one line for the whole episode
and no traceback, and a good seek afterwards works.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .bags import write_bag

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = pytest.mark.anyio

CLIENT = """
    import json
    import roslibpy
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    seek = roslibpy.Service(ros, "/rwt/player/seek", "rwt_msgs/Seek")
    status = roslibpy.Service(ros, "/rwt/player/get_status", "rwt_msgs/GetPlayerStatus")
    out = {{"bad": []}}
    for offset in (float("nan"), float("inf"), -1.0, 1e300):
        for _ in range(100):
            reply = seek.call(roslibpy.ServiceRequest({{"offset": offset}}), timeout=10)
        out["bad"].append(dict(reply))
    out["status"] = dict(status.call(roslibpy.ServiceRequest({{}}), timeout=10))
    out["good"] = dict(seek.call(roslibpy.ServiceRequest({{"offset": 0.5}}), timeout=10))
    out["after"] = dict(status.call(roslibpy.ServiceRequest({{}}), timeout=10))
    print(json.dumps(out))
    ros.terminate()
"""


async def test_hostile_seeks_are_refused_and_logged_once(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    server = ServerProcess(tmp_path, ("--play", str(bag), "--start-paused"))
    try:
        out = await run_python(CLIENT.format(port=server.port))
    finally:
        assert server.stop() == 0, server.stderr_text()
    got = json.loads(out.strip().splitlines()[-1])
    nan, inf, negative, huge = got["bad"]
    assert nan == {
        "success": False,
        "message": "seek: offset nan is not a finite number of seconds",
    }
    assert inf == {
        "success": False,
        "message": "seek: offset inf is not a finite number of seconds",
    }
    assert negative["success"] is False
    assert negative["message"] == "seek: offset -1 s is outside the bag (0 to 1.050 s)"
    assert huge["success"] is False
    assert huge["message"] == "seek: offset 1e+300 s is outside the bag (0 to 1.050 s)"
    assert got["status"]["position"] == 0.0  # nothing moved
    assert got["good"]["success"] is True
    assert got["after"]["position"] == pytest.approx(0.5)

    log = server.stderr_text()
    assert "Traceback" not in log
    refused = [ln for ln in log.splitlines() if "player_seek_refused" in ln]
    assert len(refused) == 1, refused  # 400 refusals, one episode, one line
