"""``rwt serve --webrtc --ice-server`` behind a NAT: the session connects through STUN or TURN.

The topology of tests/support/netns.py: the robot's ``rwt serve`` behind an
iptables NAT that forwards only its signalling port, the browser (an aiortc
peer, nat_peer.py, or Chromium running nat_page.py's page) behind another, and
Debian's coturn as STUN and TURN server
(docs/webrtc.md, "Through NAT"). Each test does a rosbridge round trip on the
data channel and asserts where the data went: to the NAT's public address (the
robot's server-reflexive candidate) when the NAT lets the peers meet, or to the
TURN server (its relayed candidate) when the browser can reach nothing else.
Skipped, with the reason, without root, iptables or coturn.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import quote, urlencode

import anyio
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from tests.browser.cdp import chromium_path
from tests.support import netns
from tests.support.realclients import REPO

pytestmark = pytest.mark.anyio

ENV = {**os.environ, "PYTHONPATH": f"{REPO / 'src'}:{REPO}", "PYTHONUNBUFFERED": "1"}
STUN = f"stun:{netns.TURN}:3478"
TURN = f"turn:{netns.TURN_USER}:{quote(netns.TURN_PASSWORD, safe='')}@{netns.TURN}:3478"
PEER_TIMEOUT_S = 40.0
"""Bounds a hung browser peer: a failure, not a measurement."""


@pytest.fixture
def topology(tmp_path: Path) -> Iterator[netns.Topology]:
    reason = netns.unavailable()
    if reason is not None:
        pytest.skip(reason)
    with netns.nat_topology() as built:
        yield built


async def _serve_robot(
    topology: netns.Topology, folder: Path, *ice: str, stack: str
) -> netns.Started:
    """Coturn (for ``ice``), then ``rwt serve --webrtc --webrtc-stack STACK`` with ``ice`` in
    the robot's namespace."""
    if ice:
        coturn = topology.turn.start(
            netns.coturn_argv(topology.turn, folder), folder / "coturn.log"
        )
        await coturn.wait_for(netns.COTURN_READY)
    args = ["--host", netns.ROBOT, "--port", str(netns.SIGNALLING_PORT), "--webrtc"]
    args += ["--webrtc-stack", stack]
    for url in ice:
        args += ["--ice-server", url]
    argv = [sys.executable, "-m", "rwt", "serve", "--log-level", "info", *args]
    robot = topology.robot.start(argv, folder / "robot.log", ENV)
    await robot.wait_for("listening on ws://")
    return robot


def _browser(topology: netns.Topology, *args: str) -> subprocess.CompletedProcess[str]:
    """Run nat_peer.py in the browser's namespace against the NAT's forwarded port."""
    base = f"http://{netns.NAT_PUBLIC}:{netns.SIGNALLING_PORT}"
    return subprocess.run(
        [
            "ip",
            "netns",
            "exec",
            topology.browser.ns,
            sys.executable,
            "-m",
            "tests.webrtc.nat_peer",
            base,
            *args,
        ],
        env=ENV,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=PEER_TIMEOUT_S,
        check=False,
    )


def _browser_round_trip(topology: netns.Topology, folder: Path) -> dict[str, object]:
    """The browser's round trip, with the STUN server a page would pass; its result."""
    done = _browser(topology, "--ice-server", STUN)
    robot_log = (folder / "robot.log").read_text("utf-8", "replace")
    assert done.returncode == 0, f"{done.stderr[-3000:]}\nrobot:\n{robot_log[-3000:]}"
    return json.loads(done.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


async def test_through_the_nat_directly_with_the_stun_servers_reflexive_candidate(
    topology: netns.Topology, tmp_path: Path, stack: str
) -> None:
    await _serve_robot(topology, tmp_path, STUN, stack=stack)
    result = _browser_round_trip(topology, tmp_path)
    assert result["echo"] == {"data": "through the NAT"}
    assert result["candidates"] == ["host", "srflx"]  # gathered before the answer: no trickle
    # The data went to the NAT's public address: the robot's srflx candidate.
    assert result["remote"][0] == netns.NAT_PUBLIC  # type: ignore[index]


async def test_through_turn_when_the_browser_reaches_only_the_turn_server(
    topology: netns.Topology, tmp_path: Path, stack: str
) -> None:
    topology.only_turn_reachable()
    await _serve_robot(topology, tmp_path, STUN, TURN, stack=stack)
    result = _browser_round_trip(topology, tmp_path)
    assert result["echo"] == {"data": "through the NAT"}
    assert result["candidates"] == ["host", "relay", "srflx"]  # all in the answer
    assert result["remote"][0] == netns.TURN  # type: ignore[index]  # relayed by coturn


async def test_through_turn_over_tcp_when_the_robot_may_send_no_udp_to_the_turn_server(
    topology: netns.Topology, tmp_path: Path, stack: str
) -> None:
    """``--ice-server turn:...?transport=tcp``: the robot's leg to coturn is a TCP connection."""
    if stack == "native":
        pytest.skip("the native stack refuses TURN over TCP: libjuice reaches TURN over UDP only")
    topology.only_turn_reachable()
    topology.turn_only_over_tcp()
    await _serve_robot(topology, tmp_path, f"{TURN}?transport=tcp", stack=stack)
    result = _browser_round_trip(topology, tmp_path)
    assert result["echo"] == {"data": "through the NAT"}
    assert "relay" in result["candidates"]  # type: ignore[operator]
    assert result["remote"][0] == netns.TURN  # type: ignore[index]  # relayed by coturn
    # the allocation went over TCP: with plain ``turn:`` (UDP) this block leaves no relay
    log = (tmp_path / "robot.log").read_text("utf-8", "replace")
    if stack == "reactor":  # libwebrtc's chosen pair (webrtc/reactor.py logs it)
        assert "event=webrtc_path stack=reactor candidate=relay relay=tcp" in log
    else:  # aioice's log
        assert "TURN allocation created" in log


async def test_without_ice_servers_the_peers_never_meet(
    topology: netns.Topology, tmp_path: Path, stack: str
) -> None:
    """The control: host candidates only on both sides, so no ICE pair can work."""
    robot = await _serve_robot(topology, tmp_path, stack=stack)
    done = _browser(topology, "--wait", "2")
    assert done.returncode != 0 and "TimeoutError" in done.stderr
    assert "typ srflx" not in robot.log.read_text() and done.stdout == ""


@pytest.mark.parametrize("only_turn", [False, True], ids=["direct", "relayed"])
async def test_chromium_behind_its_nat_reaches_the_robot_behind_its_own(
    topology: netns.Topology, tmp_path: Path, only_turn: bool, stack: str
) -> None:
    """Chromium's own ICE (its host candidates hidden as mDNS names) through both NATs:
    straight between them (it picks the robot's srflx candidate over its relayed one),
    or through TURN when UDP between the NATs is dropped."""
    executable = chromium_path()
    if executable is None:
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run does it as root)")
    if only_turn:
        topology.only_turn_reachable()
    await _serve_robot(topology, tmp_path, STUN, TURN, stack=stack)
    server = f"http://{netns.NAT_PUBLIC}:{netns.SIGNALLING_PORT}"
    result = await _chromium(executable, topology.browser, tmp_path, server=server, stun=STUN)
    assert "failure" not in result, result
    assert result["echo"] == {"data": "through the NAT"}
    assert result["offer_mdns"] is True  # its host address hidden, as Chromium does by default
    assert "srflx" in result["offer_types"]  # from the page's iceServers
    assert result["remote"][0] == (netns.TURN if only_turn else netns.NAT_PUBLIC)


async def _chromium(
    executable: str, browser: netns.Host, folder: Path, **query: str
) -> dict[str, object]:
    """Headless Chromium in ``browser``'s namespace running nat_page.py's page; its report."""
    result_file = folder / "result.json"
    page = browser.start(
        [sys.executable, "-m", "tests.webrtc.nat_page", "8000", str(result_file)],
        folder / "page.log",
        ENV,
    )
    await page.wait_for("page up")
    url = f"http://127.0.0.1:8000/?{urlencode(query)}"
    argv = [executable, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run"]
    argv += [f"--user-data-dir={folder / 'profile'}", "--disable-dev-shm-usage", url]
    chromium = browser.start(argv, folder / "chromium.log")
    with anyio.fail_after(PEER_TIMEOUT_S):
        while not result_file.exists() and chromium.process.poll() is None:
            await anyio.sleep(0.1)
    chromium.stop()
    assert result_file.exists(), (folder / "chromium.log").read_text()[-3000:]
    return json.loads(result_file.read_text())  # type: ignore[no-any-return]


async def test_chromium_on_the_robots_lan_connects_with_only_an_mdns_host_candidate(
    tmp_path: Path, stack: str
) -> None:
    """No ICE servers on either side, Chromium's host address hidden behind an mDNS name.

    aioice asks for the name by multicast DNS and Chromium answers, but aioice drops
    the answer (dnspython refuses its NSEC record, docs/webrtc.md "The page"); the
    session connects anyway: Chromium's checks reach the robot's host candidate, and
    the robot answers the address they came from (a peer-reflexive candidate).
    """
    reason = netns.unavailable(())
    executable = chromium_path()
    if reason is not None or executable is None:
        pytest.skip(reason or "chromium is not installed (apt-get install chromium)")
    with netns.lan() as (robot_host, browser):
        args = ["--host", netns.LAN_ROBOT, "--port", str(netns.SIGNALLING_PORT), "--webrtc"]
        args += ["--webrtc-stack", stack]
        argv = [sys.executable, "-m", "rwt", "serve", "--log-level", "info", *args]
        robot = robot_host.start(argv, tmp_path / "robot.log", ENV)
        await robot.wait_for("listening on ws://")
        server = f"http://{netns.LAN_ROBOT}:{netns.SIGNALLING_PORT}"
        result = await _chromium(executable, browser, tmp_path, server=server)
    assert "failure" not in result, result
    assert result["echo"] == {"data": "through the NAT"}
    assert result["offer_mdns"] is True and result["offer_types"] == ["host"]
    assert result["remote"][0] == netns.LAN_ROBOT
    if stack == "aiortc":  # aioice logs its try; libjuice connects the same way, quietly
        log = (tmp_path / "robot.log").read_text()
        assert re.search(
            r'Remote candidate "[0-9a-f-]+\.local" (could not be resolved|resolved)', log
        )
