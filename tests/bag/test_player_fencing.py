"""Fencing the player's services (docs/record-replay.md, "Who may drive the player").

``/rwt/player/*`` are services like any other: with ``--auth-secret-file`` a
client that has not authenticated cannot call them (its first op is refused
and the connection closed), and ``--services-glob`` patterns that leave them
out deny them with a reason. Both checked with roslibpy against ``rwt serve
--play --start-paused``: the player stays paused at 0 with nothing published.
"""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING

import pytest

from rwt_protocol.auth import rosauth_mac
from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .bags import write_bag

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = pytest.mark.anyio

SECRET = "player-secret-0123456789"

INTRUDER = """
    import json
    import roslibpy
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    out = {{}}
    try:
        reply = roslibpy.Service(ros, "/rwt/player/resume", "std_srvs/Trigger").call(
            roslibpy.ServiceRequest({{}}), timeout=3)
        out["resume"] = dict(reply)
    except Exception as exc:
        out["refused"] = str(exc)
    print(json.dumps(out))
    ros.terminate()
"""

STATUS = """
    import json
    import roslibpy
    ros = roslibpy.Ros("127.0.0.1", {port})
    {auth}
    ros.run(timeout=20)
    status = roslibpy.Service(ros, "/rwt/player/get_status", "rwt_msgs/GetPlayerStatus")
    print(json.dumps(dict(status.call(roslibpy.ServiceRequest({{}}), timeout=10))))
    ros.terminate()
"""


def _credentials() -> str:
    now = time.time()
    fields = {
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": "fresh-random-string",
        "t": int(now - 1),
        "level": "user",
        "end": int(now + 60),
    }
    mac = rosauth_mac(SECRET, **fields)  # type: ignore[arg-type]
    args = ", ".join(repr(v) for v in (mac, *fields.values()))
    return f"ros.authenticate({args})"


async def test_unauthenticated_clients_cannot_drive_the_player(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    secret = tmp_path / "secret.txt"
    secret.write_text(SECRET)
    args = ("--play", str(bag), "--start-paused", "--auth-secret-file", str(secret))
    server = ServerProcess(tmp_path, args)
    try:
        intruder = json.loads(await run_python(INTRUDER.format(port=server.port)))
        status = json.loads(await run_python(STATUS.format(port=server.port, auth=_credentials())))
    finally:
        assert server.stop() == 0, server.stderr_text()
    assert "resume" not in intruder
    assert status["paused"] is True
    assert status["published"] == 0
    assert "event=auth_failed" in server.stderr_text()


async def test_services_glob_fences_the_player(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    args = ("--play", str(bag), "--start-paused", "--services-glob", "/robot/*")
    server = ServerProcess(tmp_path, args)
    try:
        intruder = json.loads(await run_python(INTRUDER.format(port=server.port)))
    finally:
        assert server.stop() == 0, server.stderr_text()
    assert "resume" not in intruder
    assert "/rwt/player/resume is not allowed on this server" in intruder["refused"]
