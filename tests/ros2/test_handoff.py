"""The ROS 2 link's handoff runs its batches inside the graph's inflow gate and holds per topic."""

from __future__ import annotations

import asyncio

import pytest

from rwt_ros2.handoff import KEEP_NEWER, RUN_MAX, TURN_S, Handoff, Sample

pytestmark = pytest.mark.anyio


class Hold:
    """An ``InflowHold`` that waits until the test releases it."""

    def __init__(self, calls: list[str]) -> None:
        self.calls = calls
        self.release = asyncio.Event()

    async def wait(self) -> None:
        self.calls.append("hold")
        await self.release.wait()
        self.calls.append("released")


class RecordingGate:
    """An ``InflowGate`` that records its calls; ``congest`` makes the next delivery congest."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.congest = False
        self.holds: list[Hold] = []

    def begin(self) -> None:
        self.calls.append("begin")

    def end(self) -> None:
        self.calls.append("end")

    def congested(self) -> bool:
        return self.congest

    def take_hold(self, publisher: str | None = None) -> Hold | None:
        if not self.congest:
            return None
        self.congest = False
        self.holds.append(Hold(self.calls))
        return self.holds[-1]


async def settle() -> None:
    for _ in range(20):
        await asyncio.sleep(0)


def delivered(gate: RecordingGate) -> list[str]:
    return [call for call in gate.calls if call not in ("begin", "end")]


async def test_a_sample_that_congested_a_subscriber_holds_its_topic_alone() -> None:
    handoff = Handoff()
    gate = RecordingGate()

    def congesting(name: str) -> None:
        gate.calls.append(name)
        gate.congest = True  # this delivery pushed a subscriber over its high watermark

    handoff.put(congesting, "cam 1", size=10, topic="/cam")
    handoff.put(gate.calls.append, "cam 2", size=10, topic="/cam")
    handoff.put(gate.calls.append, "odom 1", size=10, topic="/odom")
    task = asyncio.create_task(handoff.drain(lambda: gate))
    await settle()
    # /cam 2 waits for the hold; /odom goes on, and so does an event that is no sample.
    # The hold starts after cam 1's turn: in it, or after it where the turn's time
    # (TURN_S) ran out at cam 1 on a busy machine; either way before /odom's next sample
    assert sorted(delivered(gate)) == ["cam 1", "hold", "odom 1"]
    assert delivered(gate)[0] == "cam 1"
    handoff.put(gate.calls.append, "cam 3", size=10, topic="/cam")
    handoff.put(gate.calls.append, "odom 2", size=10, topic="/odom")
    handoff.put(gate.calls.append, "event")
    await settle()
    assert delivered(gate)[3:] == ["odom 2", "event"]
    assert handoff.queued_bytes == 20  # the held samples still count against the bound
    gate.holds[0].release.set()
    await settle()
    assert delivered(gate)[5:] == ["released", "cam 2", "cam 3"]  # in order
    assert handoff.queued_bytes == 0
    task.cancel()
    handoff.close()


async def test_what_an_event_that_is_no_sample_congested_holds_nothing() -> None:
    handoff = Handoff()
    gate = RecordingGate()

    def congesting(name: str) -> None:
        gate.calls.append(name)
        gate.congest = True  # a reply pushed its caller over the watermark

    handoff.put(congesting, "reply")
    handoff.put(gate.calls.append, "cam 1", size=10, topic="/cam")
    task = asyncio.create_task(handoff.drain(lambda: gate))
    await settle()
    assert delivered(gate) == ["reply", "cam 1"]  # no "hold": nothing waited for
    task.cancel()
    handoff.close()


class HandClock:
    """Monotonic seconds the test (or a callback) moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _samples(names: list[str], came: list[float], source: bytes) -> list[Sample]:
    """Samples whose callback gets their name, published at ``came`` by ``source``."""
    return [((name,), 10, t, source) for name, t in zip(names, came, strict=True)]


async def test_a_loop_behind_a_steady_stream_runs_only_the_newest_span() -> None:
    clock = HandClock()
    handoff = Handoff(max_wait_s=0.0055, clock=clock, keep_newer=5)
    ran: list[str] = []
    names = [f"s{i}" for i in range(100)]  # 1 kHz for 0.1 s, while the loop was away
    handoff.put_many(ran.append, _samples(names, [i / 1000 for i in range(100)], b"p"), "/t")
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert ran == [f"s{i}" for i in range(94, 100)]  # 5.5 ms of it, the newest
    assert handoff.expired == {"/t": 94}
    assert handoff.queued_bytes == 0
    task.cancel()
    handoff.close()


async def test_a_slowed_burst_loses_only_what_the_links_history_would_have() -> None:
    # a publisher the machine slowed: 150 samples over 150 ms, far over the span, while
    # the loop was away; the newest KEEP_NEWER go, as a history of that depth keeps them
    clock = HandClock()
    handoff = Handoff(max_wait_s=0.005, clock=clock)
    ran: list[str] = []
    names = [f"s{i}" for i in range(150)]
    handoff.put_many(ran.append, _samples(names, [i / 1000 for i in range(150)], b"p"), "/t")
    handoff.put_many(ran.append, _samples(["q0"], [0.0], b"q"), "/t")  # another publisher's
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert ran == [*names[150 - KEEP_NEWER :], "q0"]
    assert handoff.expired == {"/t": 150 - KEEP_NEWER}
    task.cancel()
    handoff.close()


async def test_a_burst_within_the_span_reaches_the_loop_whole_however_late() -> None:
    clock = HandClock()
    handoff = Handoff(max_wait_s=0.005, clock=clock)
    ran: list[str] = []
    names = [f"b{i}" for i in range(300)]
    handoff.put_many(ran.append, _samples(names, [0.001] * 300, b"p"), "/t")
    clock.now += 10.0  # the loop comes very late
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert ran == names
    assert handoff.expired == {}
    task.cancel()
    handoff.close()


async def test_a_publishers_samples_are_compared_with_its_own_only() -> None:
    handoff = Handoff(max_wait_s=0.005, clock=HandClock())
    ran: list[str] = []
    # two publishers whose clocks are 60 s apart (other hosts): neither outdates the other
    handoff.put_many(ran.append, _samples(["a0", "a1"], [0.0, 0.001], b"a"), "/t")
    handoff.put_many(ran.append, _samples(["b0", "b1"], [60.0, 60.001], b"b"), "/t")
    handoff.put_many(ran.append, _samples(["a2"], [0.002], b"a"), "/t")
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert ran == ["a0", "a1", "b0", "b1", "a2"]
    task.cancel()
    handoff.close()


async def test_a_turn_runs_samples_for_turn_s_at_most_then_lets_others_run() -> None:
    clock = HandClock()
    handoff = Handoff(clock=clock)
    ran: list[str] = []
    loop = asyncio.get_running_loop()

    def slow(name: str) -> None:  # each takes 0.45 TURN_S of the loop: 3 fit in a turn
        ran.append(name)
        clock.now += TURN_S * 0.45
        if name == "s0":  # another task's work, due at the loop's next turn
            loop.call_soon(ran.append, "other")

    names = [f"s{i}" for i in range(10)]
    handoff.put_many(slow, _samples(names, [0.0] * 10, b"p"), "/t")
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert ran == [*names[:3], "other", *names[3:]]
    task.cancel()
    handoff.close()


async def test_the_taking_thread_sees_when_the_loop_is_behind() -> None:
    clock = HandClock()
    handoff = Handoff(max_wait_s=0.01, clock=clock)
    assert not handoff.behind()  # nothing queued
    handoff.put_many(print, [(("x",), 1, 0.0, b"p")], "/t")
    clock.now += 0.004
    assert not handoff.behind()  # waiting less than half the span
    clock.now += 0.002
    assert handoff.behind()
    handoff.pause_while_behind()  # returns: it sleeps at most max_wait_s
    handoff.close()
    assert not handoff.behind()


class Runs:
    """A run callback that records each run it got (the samples' names), and each sample;
    ``one`` is the samples' own callback, for a sample that goes alone."""

    def __init__(self, calls: list[str] | None = None) -> None:
        self.runs: list[list[str]] = []
        self.calls = calls

    def one(self, name: str) -> None:  # a sample with no other of its run behind it
        self.runs.append([name])
        if self.calls is not None:
            self.calls.append(name)

    def __call__(self, runs: list[tuple[object, ...]]) -> None:
        names = [str(args[0]) for args in runs]
        self.runs.append(names)
        if self.calls is not None:
            self.calls.extend(names)


async def test_a_publishers_queued_samples_go_in_runs_of_run_max_at_most() -> None:
    handoff = Handoff(clock=HandClock())
    runs = Runs()
    names = [f"s{i}" for i in range(RUN_MAX + 10)]
    handoff.put_many(runs.one, _samples(names, [0.0] * len(names), b"p"), "/t", runs)
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert runs.runs == [names[:RUN_MAX], names[RUN_MAX:]]
    assert handoff.queued_bytes == 0
    task.cancel()
    handoff.close()


async def test_a_run_is_one_topic_and_one_publisher_in_the_order_they_came() -> None:
    handoff = Handoff(clock=HandClock())
    runs = Runs()
    handoff.put_many(runs.one, _samples(["a0", "a1"], [0.0, 0.001], b"a"), "/t", runs)
    handoff.put_many(runs.one, _samples(["b0"], [5.0], b"b"), "/t", runs)
    handoff.put_many(runs.one, _samples(["a2", "a3"], [0.002, 0.003], b"a"), "/t", runs)
    handoff.put_many(runs.one, _samples(["u0", "u1"], [0.0, 0.0], b"a"), "/u", runs)
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert runs.runs == [["a0", "a1"], ["b0"], ["a2", "a3"], ["u0", "u1"]]
    task.cancel()
    handoff.close()


async def test_samples_outdated_inside_a_run_expire_and_the_rest_go() -> None:
    handoff = Handoff(max_wait_s=0.005, clock=HandClock(), keep_newer=0)
    runs = Runs()
    came = [0.0, 0.001, 0.002, 0.010]  # the first three are over 5 ms before the newest
    handoff.put_many(runs.one, _samples(["s0", "s1", "s2"], came[:3], b"p"), "/t", runs)
    task = asyncio.create_task(handoff.drain())
    await settle()
    assert runs.runs == [["s0", "s1", "s2"]]  # none was outdated while they waited
    handoff.put_many(runs.one, _samples(["x0", "x1", "x2", "x3"], came, b"p"), "/t", runs)
    await settle()
    assert runs.runs[1:] == [["x3"]]
    assert handoff.expired == {"/t": 3}
    assert handoff.queued_bytes == 0
    task.cancel()
    handoff.close()


async def test_a_run_that_congested_a_subscriber_holds_its_topic() -> None:
    handoff = Handoff(clock=HandClock())
    gate = RecordingGate()
    runs = Runs(gate.calls)
    congest_next = [True]

    def run(batch: list[tuple[object, ...]]) -> None:
        runs(batch)
        if congest_next[0]:
            gate.congest, congest_next[0] = True, False

    handoff.put_many(runs.one, _samples(["c0", "c1"], [0.0, 0.0], b"p"), "/cam", run)
    task = asyncio.create_task(handoff.drain(lambda: gate))
    await settle()
    assert delivered(gate) == ["c0", "c1", "hold"]
    handoff.put_many(runs.one, _samples(["c2", "c3"], [0.001, 0.001], b"p"), "/cam", run)
    handoff.put_many(runs.one, _samples(["o0"], [0.0], b"q"), "/odom", run)
    await settle()
    assert delivered(gate) == ["c0", "c1", "hold", "o0"]  # /cam waits, /odom goes on
    assert handoff.queued_bytes == 20
    gate.holds[0].release.set()
    await settle()
    assert delivered(gate)[4:] == ["released", "c2", "c3"]
    assert handoff.queued_bytes == 0
    task.cancel()
    handoff.close()


async def test_what_it_keeps_of_publishers_goes_with_their_last_waiting_sample() -> None:
    # A ROS 2 peer is untrusted: samples each with a fresh publisher GID (forged, or
    # publishers that come and go) must leave nothing behind once delivered or dropped.
    clock = HandClock()
    handoff = Handoff(max_wait_s=0.005, clock=clock, keep_newer=0)
    runs = Runs()
    for i in range(2000):
        handoff.put_many(runs.one, _samples([f"g{i}"], [0.0], i.to_bytes(16, "big")), "/t", runs)
    handoff.put_many(runs.one, _samples(["a0", "a1"], [0.0, 0.01], b"a"), "/t", runs)  # a0 expires
    handoff.put(runs.one, "event")
    task = asyncio.create_task(handoff.drain())
    for _ in range(50):
        await settle()
    assert [name for run in runs.runs for name in run] == [
        *(f"g{i}" for i in range(2000)),
        "a1",
        "event",
    ]
    assert handoff.expired == {"/t": 1}
    assert handoff._newest == {}  # (what would grow: one entry per publisher and topic)
    task.cancel()
    handoff.close()
