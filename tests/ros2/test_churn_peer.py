"""The churn soak's rclpy nodes leave nothing in the ROS 2 graph once they are gone.

B26's ``ros2`` front end (``benchmarks/churn_ros2.py``) makes and destroys rclpy nodes
in one process that lives on. rclpy 9 (ROS 2 Kilted) leaves a destroyed node's
``~/get_type_description`` service in the middleware while its process lives, so
every participant of the domain, ``rwt serve --ros2`` among them, kept its discovery
data: about 7.7 KB of native heap per node that came and went, which the soak had put
down to the link (docs/benchmarks.md, B26). The peer's nodes now start without that
service; what an observer of the graph sees of a node that left is checked here: none
of its services.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from typing import TYPE_CHECKING

import pytest

from rwt_ros2.node import RosNode
from tests.integration.client_harness import _LineReader

from .support import READY_S, REPO, WAIT_S, skip_without_rclpy

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

pytestmark = [skip_without_rclpy(), pytest.mark.filterwarnings("ignore::DeprecationWarning")]

CYCLES = 6
"""Nodes the peer makes and destroys before the graph is looked at."""
PEER_NODE = re.compile(r"^/soak_r2_(\d+)/")


@pytest.fixture
def observer(ros_env: Path) -> Iterator[RosNode]:
    del ros_env
    node = RosNode("churn_observer")
    node.start()
    try:
        yield node
    finally:
        node.close()


def _peer_services(observer: RosNode) -> dict[int, list[str]]:
    """The services in the graph of the peer's churned nodes, by the node's number."""
    found: dict[int, list[str]] = {}
    for name, _ in observer.node.get_service_names_and_types():
        if (match := PEER_NODE.match(name)) is not None:
            found.setdefault(int(match[1]), []).append(name)
    return found


def test_a_node_the_churn_peer_destroyed_leaves_no_service_behind(observer: RosNode) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.churn_ros2", "--hz", "4", "--steps", "node"],
        cwd=REPO,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )
    lines = _LineReader(proc.stdout, "churn-peer")
    try:
        assert lines.get(time.monotonic() + READY_S) == "ready"
        # discovery works: the observer sees a live node's services (a node lives a quarter
        # of a second; under load discovery may miss a few, never all for long)
        deadline = time.monotonic() + WAIT_S
        while not _peer_services(observer):
            assert time.monotonic() < deadline, "the observer saw no node of the peer"
            time.sleep(0.05)
        done, deadline = 0, time.monotonic() + CYCLES * WAIT_S
        while done < CYCLES:  # a line comes once its cycle's node is destroyed
            line = lines.get(deadline)
            assert line is not None and '"ok": true' in line, line
            done = int(json.loads(line)["cycle"]) + 1
        # the process lives on, making more nodes; those it destroyed leave the graph
        left: dict[int, list[str]] = {}
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:  # their departure takes discovery a moment
            left = {n: names for n, names in _peer_services(observer).items() if n < done}
            if not left:
                break
            time.sleep(0.1)
        assert left == {}
    finally:
        proc.terminate()
        proc.wait(10)
        if proc.stdout is not None:
            proc.stdout.close()
