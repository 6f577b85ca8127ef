"""`rwt serve` starts without what only some features need (benchmarks B11, base memory).

The idle default server (in-memory graph, rosapi, TF) must stay small: modules
that only png compression, video, depth clouds, bags or the conformance runner use load
with their first use, and pydantic builds an op's validator with the first frame
of that op. A subprocess, so this test sees a fresh interpreter.
"""

from __future__ import annotations

import os
import subprocess
import sys

from tests.support.realclients import REPO

ENV = {**os.environ, "PYTHONPATH": str(REPO / "src")}

#: Loaded on first use only.
LAZY = (
    "PIL",
    "numpy",
    "cbor2",
    "av",
    "rich",
    "rwt_conformance.runner",
    "rwt_video.server",
    "rwt_graph.media.depthcloud",
    "rwt_bag.jobs",
    "rosbags.rosbag2.writer",
    "rosbags.highlevel",
)

SCRIPT = """
import sys

import anyio

import rwt_cli.app
import rwt_cli.serve  # everything `rwt serve` imports (the CLI loads a command when it runs)
from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_protocol.codecs.json import parse_object
from rwt_protocol.ops import OP_MODELS
from rwt_transports.server import RosbridgeServer, ServerConfig


def built() -> list[str]:
    return sorted(name for name, model in OP_MODELS.items() if model.__pydantic_complete__)


async def main() -> None:
    server = RosbridgeServer(Graph(TypeRegistry()), ServerConfig(port=0))  # rosapi, TF
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        print("loaded:", *sorted(set(sys.argv[1:]) & set(sys.modules)))
        print("built:", *built())
        parse_object({"op": "subscribe", "topic": "/a"})
        print("built:", *built())
        server.stop()


anyio.run(main)
"""


def test_idle_server_loads_no_feature_module_and_builds_no_op_validator() -> None:
    result = subprocess.run(
        [sys.executable, "-c", SCRIPT, *LAZY],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["loaded:", "built:", "built: subscribe"]
