"""The differential run: the real rosbridge_suite (ROS 1) and rwt's ROS 1 dialect, in one run.

The peer is found through ``RWT_ROSBRIDGE_ROS1_URL`` (a running rosbridge_websocket
with rosapi, rosbridge_suite 0.11.x); without it the comparison is skipped.
"""

from __future__ import annotations

import os

import pytest

from conformance import differential
from rwt_conformance import Outcome, Profile

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
