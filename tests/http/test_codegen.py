"""A client generated from the OpenAPI document by openapi-python-client drives the robot.

The generator is a tool, not a dependency of the tests (its typer pin is older than
rwt's): it runs from an environment of its own (tests/support/openapi_client.py), named
by ``RWT_OPENAPI_PYTHON_CLIENT``, on PATH, or made once under ``~/.cache/rwt-tests``
(``.ci/run`` makes it before the suite). The test is skipped only where none can be made.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.openapi_client import openapi_generator

from .support import api_server, curl

pytestmark = pytest.mark.anyio

PACKAGE = "rwt_http_api_client"  # from the document's title, "rwt HTTP API"


async def test_a_generated_client_publishes_reads_and_calls(tmp_path: Path) -> None:
    generator, why = await anyio.to_thread.run_sync(openapi_generator)  # made once, if not
    if generator is None:
        pytest.skip(why)
    graph = Graph()
    velocity = graph.create_publisher("/velocity", "geometry_msgs/msg/Twist", latch=True)
    graph.create_subscription("/cmd_vel", velocity.publish, "geometry_msgs/msg/Twist")
    graph.create_service("/lights", "std_srvs/srv/SetBool", lambda r: {"success": r["data"]})
    async with api_server(graph) as (_, url):
        await _generate(generator, url, tmp_path)
        sys.path.insert(0, str(tmp_path / "out"))
        try:
            results = await anyio.to_thread.run_sync(_use_the_client, url)
        finally:
            sys.path.remove(str(tmp_path / "out"))
            for name in [n for n in sys.modules if n.split(".")[0] == PACKAGE]:
                del sys.modules[name]
    lights, echoed = results
    assert lights.success is True
    assert echoed.linear.x == 0.5 and echoed.angular.z == 0.0


async def test_a_generated_client_has_only_what_the_split_globs_allow(tmp_path: Path) -> None:
    generator, why = await anyio.to_thread.run_sync(openapi_generator)
    if generator is None:
        pytest.skip(why)
    graph = Graph()
    graph.create_subscription("/cmd_vel", lambda msg: None, "geometry_msgs/msg/Twist")
    graph.create_publisher("/odom", "nav_msgs/msg/Odometry")
    access = AccessPolicy(topics_pub=("/cmd_vel",), topics_sub=("/odom",))
    config = ServerConfig(tf=False, session=SessionConfig(access=access))
    async with api_server(graph, config) as (_, url):
        await _generate(generator, url, tmp_path)
    operations = {path.stem for path in (tmp_path / "out" / PACKAGE / "api").rglob("*.py")}
    assert {"publish_cmd_vel", "get_odom", "stream_odom"} <= operations
    assert not {"get_cmd_vel", "stream_cmd_vel", "publish_odom"} & operations


async def _generate(generator: Path, url: str, folder: Path) -> None:
    """The client of ``url``'s document, generated into ``folder / "out"``."""
    status, document = await curl(f"{url}/openapi.json")
    assert status == 200
    (folder / "openapi.json").write_text(document, "utf-8")
    command = [str(generator), "generate", "--path", "openapi.json", "--output-path", "out"]
    generated = await anyio.to_thread.run_sync(
        lambda: subprocess.run(command, check=False, cwd=folder, capture_output=True, text=True)
    )
    assert generated.returncode == 0, generated.stdout + generated.stderr


def _use_the_client(url: str) -> tuple[Any, Any]:
    client_module = importlib.import_module(f"{PACKAGE}.client")
    default = f"{PACKAGE}.api.default"
    call_lights = importlib.import_module(f"{default}.call_lights")
    publish_cmd_vel = importlib.import_module(f"{default}.publish_cmd_vel")
    get_velocity = importlib.import_module(f"{default}.get_velocity")
    models = importlib.import_module(f"{PACKAGE}.models")
    client = client_module.Client(base_url=url)
    lights = call_lights.sync(client=client, body=models.SetBoolRequest(data=True))
    twist = models.Twist.from_dict({"linear": {"x": 0.5, "y": 0, "z": 0}})
    publish_cmd_vel.sync(client=client, body=twist)  # the robot echoes it on /velocity
    return lights, get_velocity.sync(client=client)
