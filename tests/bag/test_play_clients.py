"""Bags written by rosbags (ROS 1, ROS 2 sqlite3, ROS 2 MCAP) played by `rwt serve --play`.

The server starts paused (--start-paused); a real client (roslibpy, or roslib in
Node) subscribes, calls /rwt/player/resume, and records when each message
arrives. Content is checked field by field for every standard type in the bag
(tf2_msgs/TFMessage, sensor_msgs/Image, sensor_msgs/PointCloud2,
nav_msgs/OccupancyGrid, std_msgs/String), and a late subscriber on a new
connection gets the latched /tf_static after playback.

Timing: the gaps between consecutive /chatter arrivals must match the bag's gaps
(50 ms) divided by the rate within 5 ms. Measured on the receiving side, a gap
also carries the client's scheduling noise, so on a shared machine the test
asks for the median deviation within 5 ms and all but at most 5 of the 20
arrivals within 5 ms of the bag's schedule (late wake-ups of a busy client, seen
on 2 cores shared with other jobs, are not the player's timing). A playback that
misses this is played again, up to ``PLAYBACKS`` times in all: a stall of the
machine passes, while a player with wrong gaps fails every playback.
benchmarks/ measures the player's own accuracy (p50/p99).
"""

from __future__ import annotations

import base64
import itertools
import json
import statistics
from pathlib import Path
from typing import Any

import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import node_missing, run_node, run_python

from .bags import CHATTER, CHATTER_GAP_S, IMAGE, MAP, POINTS, write_bag

pytestmark = pytest.mark.anyio

TOPICS = {
    "/chatter": "std_msgs/String",
    "/tf": "tf2_msgs/TFMessage",
    "/camera": "sensor_msgs/Image",
    "/points": "sensor_msgs/PointCloud2",
    "/map": "nav_msgs/OccupancyGrid",
}
TOLERANCE_S = 0.005
OUTLIERS = 5  # of 20 arrivals: a quarter, for a busy shared machine
PLAYBACKS = 3


def roslibpy_client(port: int) -> str:
    return f"""
        import json, time
        import roslibpy
        ros = roslibpy.Ros("127.0.0.1", {port})
        ros.run(timeout=20)
        got = {{}}
        def keep(name):
            return lambda msg: got.setdefault(name, []).append([time.monotonic(), msg])
        for name, type_name in {TOPICS!r}.items():
            roslibpy.Topic(ros, name, type_name).subscribe(keep(name))
        time.sleep(0.5)
        resume = roslibpy.Service(ros, "/rwt/player/resume", "std_srvs/Trigger")
        assert resume.call(roslibpy.ServiceRequest({{}}), timeout=10)["success"]
        deadline = time.monotonic() + 20
        while len(got.get("/chatter", [])) < {CHATTER} and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.3)
        late_ros = roslibpy.Ros("127.0.0.1", {port})
        late_ros.run(timeout=20)
        late = []
        roslibpy.Topic(late_ros, "/tf_static", "tf2_msgs/TFMessage").subscribe(late.append)
        deadline = time.monotonic() + 10
        while not late and time.monotonic() < deadline:
            time.sleep(0.02)
        got["late /tf_static"] = [[0, m] for m in late]
        print(json.dumps(got))
        ros.terminate()
    """


def roslib_client(port: int) -> str:
    return f"""
        import * as ROSLIB from "roslib";
        import {{ performance }} from "node:perf_hooks";
        const fail = setTimeout(() => {{ console.error("timed out"); process.exit(2); }}, 40000);
        const url = "ws://127.0.0.1:{port}";
        const ros = new ROSLIB.Ros({{ url }});
        const got = {{}};
        for (const [name, messageType] of Object.entries({json.dumps(TOPICS)})) {{
          new ROSLIB.Topic({{ ros, name, messageType }}).subscribe((msg) => {{
            (got[name] ??= []).push([performance.now() / 1000, msg]);
          }});
        }}
        const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
        await sleep(500);
        const resume = new ROSLIB.Service({{
          ros, name: "/rwt/player/resume", serviceType: "std_srvs/Trigger" }});
        await new Promise((ok, no) => resume.callService({{}}, ok, no));
        for (let i = 0; i < 1000 && (got["/chatter"] ?? []).length < {CHATTER}; i++) {{
          await sleep(20);
        }}
        await sleep(300);
        const late = new ROSLIB.Ros({{ url }});
        const staticMsgs = await new Promise((ok) => {{
          const kept = [];
          new ROSLIB.Topic({{ ros: late, name: "/tf_static", messageType: "tf2_msgs/TFMessage" }})
            .subscribe((m) => {{ kept.push(m); ok(kept); }});
        }});
        got["late /tf_static"] = staticMsgs.map((m) => [0, m]);
        console.log(JSON.stringify(got));
        clearTimeout(fail);
        ros.close(); late.close();
    """


def _secs(stamp: dict[str, int]) -> float:
    return (
        stamp.get("sec", stamp.get("secs", 0)) + stamp.get("nanosec", stamp.get("nsecs", 0)) / 1e9
    )


def check_content(got: dict[str, list[Any]]) -> None:
    """Every topic arrived whole, with the values the bag holds."""
    chatter = [m["data"] for _, m in got["/chatter"]]
    assert chatter == [f"chatter {i} ✓" for i in range(CHATTER)]
    tf = [m["transforms"] for _, m in got["/tf"]]
    assert [t[0]["transform"]["translation"]["x"] for t in tf] == [i / 10 for i in range(10)]
    assert {t[0]["header"]["frame_id"] for t in tf} == {"odom"}
    assert {t[0]["child_frame_id"] for t in tf} == {"base_link"}
    images = [m for _, m in got["/camera"]]
    assert len(images) == 3
    for image in images:
        assert (image["height"], image["width"], image["encoding"], image["step"]) == (
            4,
            8,
            "rgb8",
            24,
        )
        assert base64.b64decode(image["data"]) == IMAGE
    clouds = [m for _, m in got["/points"]]
    assert len(clouds) == 2
    for cloud in clouds:
        assert [f["name"] for f in cloud["fields"]] == ["x", "y", "z"]
        assert [f["offset"] for f in cloud["fields"]] == [0, 4, 8]
        assert base64.b64decode(cloud["data"]) == POINTS.tobytes()
        assert (cloud["width"], cloud["point_step"], cloud["is_dense"]) == (3, 12, True)
    (grid,) = [m for _, m in got["/map"]]
    assert grid["data"] == MAP
    assert (grid["info"]["width"], grid["info"]["height"], grid["info"]["resolution"]) == (
        3,
        2,
        0.5,
    )
    assert grid["info"]["origin"]["position"] == {"x": -1.0, "y": -2.0, "z": 0.0}
    (late,) = [m for _, m in got["late /tf_static"]]
    pairs = [(t["header"]["frame_id"], t["child_frame_id"]) for t in late["transforms"]]
    assert pairs == [("map", "odom"), ("base_link", "laser")]
    assert _secs(late["transforms"][0]["header"]["stamp"]) == 1_700_000_000


def check_timing(got: dict[str, list[Any]], rate: float) -> None:
    """The /chatter arrivals keep the bag's gaps divided by the rate (see the module docstring).

    Each arrival is compared with its place on the bag's schedule (i gaps after
    the first), aligned on the median offset, so one late wake-up counts once
    rather than lengthening one gap and shortening the next.
    """
    arrivals = [t for t, _ in got["/chatter"]]
    want = CHATTER_GAP_S / rate
    offsets = [t - arrivals[0] - i * want for i, t in enumerate(arrivals)]
    centre = statistics.median(offsets)
    deviations = [abs(o - centre) for o in offsets]
    late = [round(d * 1000, 1) for d in deviations if d > TOLERANCE_S]
    gaps = [round((b - a) * 1000, 1) for a, b in itertools.pairwise(arrivals)]
    assert statistics.median(deviations) <= TOLERANCE_S, (want, gaps)
    assert len(late) <= OUTLIERS, f"off the schedule by over 5 ms: {late} (ms); gaps: {gaps}"


CASES = [
    pytest.param("mcap", "roslibpy", 1.0, id="mcap-roslibpy-rate1"),
    pytest.param("sqlite3", "roslibpy", 2.0, id="sqlite3-roslibpy-rate2"),
    pytest.param("ros1", "roslibpy", 1.0, id="ros1-roslibpy-rate1"),
    pytest.param("mcap", "roslib", 2.0, id="mcap-roslib-rate2", marks=pytest.mark.node),
    pytest.param("ros1", "roslib", 1.0, id="ros1-roslib-rate1", marks=pytest.mark.node),
]


async def play_to_client(tmp_path: Path, bag: Path, fmt: str, client: str, rate: float) -> Any:
    """One `rwt serve --play` of ``bag`` received by ``client``: what it got, per topic."""
    # no --dialect: a ROS 1 bag makes a ROS 1 graph by itself
    args = ["--play", str(bag), "--start-paused", "--rate", str(rate)]
    server = ServerProcess(tmp_path, tuple(args))
    try:
        if client == "roslibpy":
            out = await run_python(roslibpy_client(server.port))
        else:
            out = await run_node(roslib_client(server.port))
    finally:
        code = server.stop()
    assert code == 0, server.stderr_text()
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.parametrize(("fmt", "client", "rate"), CASES)
async def test_rosbags_bag_played_to_clients(
    tmp_path: Path, fmt: str, client: str, rate: float
) -> None:
    if client == "roslib" and node_missing():
        pytest.skip(str(node_missing()))
    bag = write_bag(tmp_path / "robot", fmt)
    for playback in range(1, PLAYBACKS + 1):
        got = await play_to_client(tmp_path, bag, fmt, client, rate)
        check_content(got)
        try:
            check_timing(got, rate)
        except AssertionError:
            if playback == PLAYBACKS:
                raise
        else:
            return
