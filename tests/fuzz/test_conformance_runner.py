"""Fuzzed hostile servers against the conformance runner (its inputs are the server's frames).

The grammar's ``server_frames`` draws bursts a hostile server answers every frame
with: server ops with hostile fields (JSON or CBOR) and raw frames (nested past any
limit, not UTF-8, lone surrogates, undecodable). The runner must decode each
without raising, and a run against such a server must end with every case judged
(failed or passed, never a runner error), its details printable.
"""

from __future__ import annotations

import random
from collections.abc import Iterator

import anyio
import cbor2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_conformance import Outcome, RunOptions, run_suite
from rwt_conformance.frames import decode_frame
from rwt_conformance.match import describe, match
from rwt_conformance.model import Dialect
from rwt_conformance.versions import SpecVersion
from tests.conformance import hostile
from tests.fuzz import grammar
from tests.fuzz.conftest import FUZZ
from tests.support.shipped_suite import SUITE

CASES = ("topics.publish-example",)
seeded = st.randoms(use_true_random=False)


@FUZZ
@given(rng=seeded)
def test_every_server_frame_decodes_without_raising(rng: random.Random) -> None:
    for data, binary in grammar.server_frames(rng):
        frame = data if binary else data.decode("utf-8", "replace")  # as the connector does
        received = decode_frame(frame)
        assert received.size == len(frame)
        if received.problem is None:  # a judged frame can be matched and shown
            match({"op": "publish"}, received.value, {})
            describe(received.value, 100).encode("utf-8")


class Script:
    """The burst the hostile server answers with, set per example."""

    def __init__(self) -> None:
        self.burst: list[tuple[bytes, bool]] = []

    def __call__(self) -> list[tuple[bytes, bool]]:
        return self.burst


@pytest.fixture(scope="module")
def scripted() -> Iterator[tuple[str, Script]]:
    script = Script()
    with hostile.serving(hostile.answering(script), max_size=None) as url:
        yield url, script


def _options(url: str) -> RunOptions:
    """What is fuzzed is how frames are judged, so the run waits as little as it can: the
    dialect and spec version given (nothing to detect, which waits for answers a hostile
    burst never holds), and no retry (a retried case waits twice)."""
    return RunOptions(
        url,
        only=CASES,
        expect_timeout_s=0.3,
        case_timeout_s=10,
        retry_budget_s=0,
        dialect=Dialect.ROS2,
        spec_version=SpecVersion.of(2, 1),
    )


def test_a_run_against_fuzzed_servers_judges_every_case(scripted: tuple[str, Script]) -> None:
    url, script = scripted

    @settings(FUZZ, max_examples=min(FUZZ.max_examples, 40))
    @given(rng=seeded)
    def one_run(rng: random.Random) -> None:
        script.burst = grammar.server_frames(rng)
        options = _options(url)

        async def run() -> None:
            with anyio.fail_after(60):
                result = await run_suite(SUITE, options)
            assert [c.case.id for c in result.cases] == list(CASES)
            for case in result.cases:
                assert case.outcome in (Outcome.FAILED, Outcome.PASSED)
                assert "runner error" not in case.detail, case.detail
                case.detail.encode("utf-8")  # printable: reports and the console encode it

        anyio.run(run, backend="asyncio")

    one_run()


def test_a_fragment_named_by_an_integer_too_long_to_print_is_judged(
    scripted: tuple[str, Script],
) -> None:
    # CBOR carries integers of any size; Python refuses to print one of 5,000 digits
    url, script = scripted
    part = {"op": "fragment", "id": 10**5000, "num": 0, "total": 2, "data": '{"op":'}
    script.burst = [(cbor2.dumps(part), True)]
    options = _options(url)

    async def run() -> None:
        result = await run_suite(SUITE, options)
        (case,) = result.cases
        assert case.outcome is Outcome.FAILED
        assert "runner error" not in case.detail, case.detail

    anyio.run(run, backend="asyncio")
