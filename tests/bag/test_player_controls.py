"""The player's /rwt/player services, /clock and rosapi get_time, driven by roslibpy.

`rwt serve --play BAG --clock 50 --start-paused`: a web page (here roslibpy)
reads the status, sees bag time through rosapi get_time and /clock, seeks,
resumes and pauses, and receives the messages from the sought position on.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .bags import T0, write_bag

pytestmark = pytest.mark.anyio

CLIENT = """
    import json, time
    import roslibpy
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    def call(name, type_name, args=None):
        service = roslibpy.Service(ros, "/rwt/player/" + name, type_name)
        return dict(service.call(roslibpy.ServiceRequest(args or {{}}), timeout=10))
    out = {{}}
    out["status0"] = call("get_status", "rwt_msgs/GetPlayerStatus")
    out["time0"] = dict(ros.get_time())
    clock = []
    roslibpy.Topic(ros, "/clock", "rosgraph_msgs/Clock").subscribe(clock.append)
    time.sleep(0.3)
    out["clock_paused"] = list(clock)
    out["seek"] = call("seek", "rwt_msgs/Seek", {{"offset": 0.5}})
    out["status1"] = call("get_status", "rwt_msgs/GetPlayerStatus")
    out["time1"] = dict(ros.get_time())
    chatter = []
    words = roslibpy.Topic(ros, "/chatter", "std_msgs/String")
    words.subscribe(lambda m: chatter.append(m["data"]))
    time.sleep(0.3)
    out["resume"] = call("resume", "std_srvs/Trigger")
    time.sleep(0.25)
    out["pause"] = call("pause", "std_srvs/Trigger")
    out["status2"] = call("get_status", "rwt_msgs/GetPlayerStatus")
    time.sleep(0.2)
    out["chatter"] = list(chatter)
    out["clock_last"] = clock[-1]
    print(json.dumps(out))
    ros.terminate()
"""


def _seconds(stamp: dict) -> float:
    sec = stamp.get("sec", stamp.get("secs"))
    nsec = stamp.get("nanosec", stamp.get("nsecs"))
    return sec + nsec / 1e9


async def test_player_services_clock_and_get_time(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    server = ServerProcess(tmp_path, ("--play", str(bag), "--clock", "50", "--start-paused"))
    try:
        out = await run_python(CLIENT.format(port=server.port))
    finally:
        assert server.stop() == 0, server.stderr_text()
    got = json.loads(out.strip().splitlines()[-1])
    t0 = T0 / 1e9

    status0 = got["status0"]
    assert status0["paused"] is True
    assert status0["position"] == 0.0
    assert status0["duration"] == pytest.approx(1.05)
    assert status0["rate"] == 1.0
    assert status0["published"] == 0
    assert _seconds(got["time0"]) == pytest.approx(t0)
    assert got["clock_paused"], "no /clock while paused"
    assert [_seconds(c["clock"]) for c in got["clock_paused"]] == pytest.approx(
        [t0] * len(got["clock_paused"])
    )

    assert got["seek"]["success"] is True
    assert got["status1"]["position"] == pytest.approx(0.5)
    assert got["status1"]["paused"] is True
    assert _seconds(got["time1"]) == pytest.approx(t0 + 0.5)

    assert got["resume"]["success"] and got["pause"]["success"]
    status2 = got["status2"]
    assert status2["paused"] is True
    assert 0.5 < status2["position"] < 1.05
    # from the sought position on (chatter i is at 0.1 + 0.05 i s), nothing before
    first = int(got["chatter"][0].split()[1])
    assert first == 8
    assert got["chatter"] == [f"chatter {i} ✓" for i in range(8, 8 + len(got["chatter"]))]
    # paused: /clock stands at the position reported
    assert _seconds(got["clock_last"]["clock"]) == pytest.approx(t0 + status2["position"], abs=1e-6)
