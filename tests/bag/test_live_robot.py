"""A bag served by `rwt serve --play --video` looks like a live robot to web clients.

roslibpy's TFClient gets the bag's transforms through the built-in
tf2_web_republisher (map -> odom from the latched /tf_static, odom -> base_link
from /tf, composed), and an HTTP client gets the bag's image from the video
server's snapshot URL, as web_video_server serves it.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .bags import IMAGE, write_bag

pytestmark = pytest.mark.anyio

TF_CLIENT = """
    import json, time
    import roslibpy
    import roslibpy.tf
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    got = []
    client = roslibpy.tf.TFClient(ros, fixed_frame="map", angular_threshold=0.01,
                                  translation_threshold=0.01, rate=20.0)
    client.subscribe("base_link", lambda t: got.append(t["translation"]["x"]))
    time.sleep(0.5)
    resume = roslibpy.Service(ros, "/rwt/player/resume", "std_srvs/Trigger")
    assert resume.call(roslibpy.ServiceRequest({{}}), timeout=10)["success"]
    deadline = time.monotonic() + 20
    while len(got) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    print(json.dumps(got))
    ros.terminate()
"""


async def test_tf_and_video_of_a_played_bag(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    # paused until the TF client is subscribed; looping so the snapshot gets a new image
    args = ("--play", str(bag), "--start-paused", "--loop", "--video", "--video-port", "0")
    server = ServerProcess(tmp_path, args)
    try:
        video_line = server.next_stdout_line()
        assert video_line is not None and video_line.startswith("video on http://"), video_line
        video = video_line.removeprefix("video on ")
        out = await run_python(TF_CLIENT.format(port=server.port))
        async with httpx.AsyncClient(timeout=20) as http:
            snapshot = await http.get(f"{video}/snapshot", params={"topic": "/camera"})
    finally:
        assert server.stop() == 0, server.stderr_text()
    xs = json.loads(out.strip().splitlines()[-1])
    assert len(xs) >= 3
    # map -> odom is 1.0 along x (static); odom -> base_link is 0.0 .. 0.9 (the bag's /tf)
    assert all(1.0 <= x <= 1.9 + 1e-9 for x in xs), xs
    assert len({round(x, 3) for x in xs}) >= 2, "the transform did not move"
    assert snapshot.status_code == 200
    assert snapshot.headers["content-type"] == "image/jpeg"
    pixels = np.asarray(Image.open(io.BytesIO(snapshot.content)).convert("RGB"))
    assert pixels.shape == (4, 8, 3)
    want = np.frombuffer(IMAGE, dtype=np.uint8).reshape(4, 8, 3).astype(int)
    assert np.abs(pixels.astype(int) - want).mean() < 12  # JPEG is lossy
