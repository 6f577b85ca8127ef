"""The differential run: the real rosbridge_suite (ROS 1) and rwt's ROS 1 dialect, in one run.

The peer is found through ``RWT_ROSBRIDGE_ROS1_URL`` (a running rosbridge_websocket
with rosapi, rosbridge_suite 0.11.x); without it the comparison is skipped.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from conformance import differential
from rwt_conformance import Outcome, Profile
from rwt_conformance.model import Dialect
from rwt_conformance.runner import AS_THE_REFERENCE
from tests.support.cli import RWT
from tests.support.shipped_suite import SUITE

PEER = os.environ.get(differential.PEER_ENV)
needs_peer = pytest.mark.skipif(
    not PEER,
    reason=f"{differential.PEER_ENV} is not set: no rosbridge_suite (ROS 1, 0.11.x) to compare"
    " with; start rosbridge_websocket and rosapi on Debian's ROS 1 packages and give its URL",
)


@needs_peer
@pytest.mark.anyio
async def test_both_servers_pass_the_reference_profile_in_the_same_run() -> None:
    assert PEER is not None
    [result] = await differential.run(PEER, [Profile.REFERENCE])
    failed = {
        name: [(c.case.id, c.detail) for c in run.cases if c.outcome is Outcome.FAILED]
        for name, run in (("peer", result.peer), ("rwt", result.rwt))
    }
    assert failed == {"peer": [], "rwt": []}
    assert result.differing() == []
    # the reference skips only what 0.11 lacks (actions), what needs a secret or TCP,
    # and rwt's own decisions; each with its reason
    skipped = {c.case.id: c.detail for c in result.peer.cases if c.outcome is Outcome.SKIPPED}
    lacking = {case for case, why in skipped.items() if "0.11" in why}
    assert lacking == {case for case in skipped if case.startswith("actions.")} | {
        "connections.frame-limit"
    }
    assert all(why for why in skipped.values())
    assert "0 failed" in differential.render([result])


def test_without_a_peer_the_script_says_how_to_give_one(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(differential.PEER_ENV, raising=False)
    assert differential.main([]) == 0
    said = capsys.readouterr().err
    assert "skipped" in said and differential.PEER_ENV in said


@pytest.mark.anyio
async def test_a_server_that_is_not_ros1_is_refused_as_the_peer() -> None:
    with pytest.raises(ConnectionError, match="not a ROS 1 rosbridge server"):
        await differential.run("ws://127.0.0.1:1", [Profile.REFERENCE], timeout_s=0.5)


PEER2 = os.environ.get(differential.PEER2_ENV)
needs_ros2_peer = pytest.mark.skipif(
    not PEER2,
    reason=f"{differential.PEER2_ENV} is not set: no rosbridge_suite (ROS 2, 2.1.0) to compare"
    " with; start rosbridge_websocket and rosapi_node of rosbridge_suite 2.1.0 and give its URL",
)
LACKING_IN_2_1_0 = {
    "actions.goal-to-nobody",
    "actions.concurrent-goals",
    "services.timeout-and-self-call",
    "services.unadvertise",
}
"""Cases the reference profile cannot judge against 2.1.0 (docs/reference-behaviour.md)."""


@needs_ros2_peer
@pytest.mark.anyio
async def test_rosbridge_suite_2_1_0_passes_the_reference_profile() -> None:
    assert PEER2 is not None
    [result] = await differential.run(PEER2, [Profile.REFERENCE], dialect=Dialect.ROS2)
    failed = {
        name: [(c.case.id, c.detail) for c in run.cases if c.outcome is Outcome.FAILED]
        for name, run in (("peer", result.peer), ("rwt", result.rwt))
    }
    assert failed == {"peer": [], "rwt": []}
    # 2.1.0 passes the cases recording its defects its own way (REF §12), rwt the spec's
    recorded = {c.id for c in SUITE.cases if c.defects(Profile.REFERENCE, Dialect.ROS2)}
    peer_way = {c.case.id for c in result.peer.cases if c.detail.startswith(AS_THE_REFERENCE)}
    assert peer_way == recorded
    assert not any(c.detail for c in result.rwt.cases if c.case.id in recorded)
    skipped = {c.case.id: c.detail for c in result.peer.cases if c.outcome is Outcome.SKIPPED}
    assert {case for case, why in skipped.items() if "2.1.0" in why} == LACKING_IN_2_1_0
    assert all(why for why in skipped.values())


@needs_ros2_peer
def test_rwt_conformance_against_2_1_0_passes_and_says_why_it_skips() -> None:
    assert PEER2 is not None
    done = subprocess.run(
        [*RWT, "conformance", PEER2, "--profile", "reference"],
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "src")},
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-3000:]
    assert "dialect: ros2 (/rosapi/get_ros_version says 2)" in done.stdout
    assert " 0 failed, " in done.stdout
    assert "rosbridge_suite 2.1.0 waits for ever for an action server" in done.stdout


def test_without_a_ros2_peer_the_script_says_how_to_give_one(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(differential.PEER2_ENV, raising=False)
    assert differential.main(["--dialect", "ros2"]) == 0
    said = capsys.readouterr().err
    assert "skipped" in said and differential.PEER2_ENV in said and "2.1.0" in said
