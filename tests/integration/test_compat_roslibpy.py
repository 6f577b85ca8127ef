"""``rwt serve --compat rosbridge`` with roslibpy 2.1.0, which has no handler for ``status``.

roslibpy logs a traceback for every op it has no handler for; rosbridge_suite sends
none of them, so its users' logs stay clean. In compat mode rwt sends none either,
and a missing service is answered in rosbridge_suite's words (docs/differences.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tests.integration.client_harness import run_client_script

if TYPE_CHECKING:
    from pathlib import Path

REFUSED_OPS = """
import json, logging, time
import roslibpy

logging.basicConfig(level=logging.INFO)
ros = roslibpy.Ros("127.0.0.1", {port})
ros.run(timeout=20)
roslibpy.Topic(ros, "/a", "no_such_pkg/msg/Nope").subscribe(lambda msg: None)
roslibpy.Topic(ros, "/b", "std_msgs/msg/String").publish(roslibpy.Message({{"data": 1}}))
roslibpy.Topic(ros, "/c", "not a type").advertise()
ros.send_on_ready(roslibpy.Message({{"op": "no_such_op"}}))
failed = []
service = roslibpy.Service(ros, "/nope", "std_srvs/srv/Empty")
service.call(roslibpy.ServiceRequest(), lambda response: None, failed.append)
deadline = time.monotonic() + 10
while not failed and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.5)  # any status sent after the reply arrives meanwhile
print(json.dumps({{"failed": failed}}), flush=True)
ros.terminate()
"""


def refused_ops(tmp_path: Path, *args: str) -> tuple[dict, str]:
    """What roslibpy's failure callback got, and everything roslibpy logged."""
    got, logged, _ = run_client_script(tmp_path, args, REFUSED_OPS)
    return got, logged


def test_roslibpy_logs_no_traceback_for_refused_ops_in_compat_mode(tmp_path: Path) -> None:
    got, logged = refused_ops(tmp_path, "--compat", "rosbridge")
    assert got == {"failed": ["Service /nope does not exist"]}
    assert "Traceback" not in logged, logged


def test_roslibpy_logs_a_traceback_for_each_status_by_default(tmp_path: Path) -> None:
    # what the mode is for: rwt's statuses, which roslibpy 2.1.0 cannot handle
    got, logged = refused_ops(tmp_path)
    assert got == {"failed": ["service /nope does not exist"]}
    assert logged.count("Traceback") >= len(["subscribe", "publish", "advertise", "op", "call"])
