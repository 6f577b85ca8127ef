"""Runs conformance cases against a rosbridge server over real connections.

Each case gets fresh connections (opened on first use, closed at the end), its
own names (``${ns}`` is unique per case and run, so cases never see each
other's topics) and a bounded time: every wait and every send is bounded by
the step's timeout, the whole case by ``case_timeout_s`` and each close by
``bounds.CLOSE_TIMEOUT_S``.

The server is not trusted (``bounds``): a frame over ``max_frame_bytes`` closes
its connection, a frame nested too deeply or more unconsumed frames than
``case_budget_bytes`` fail the case at once, each with its reason; the run
goes on with the next case.

A ``sync`` is a round trip through a topic private to the connection: the
connection publishes a token on it and waits for the token to come back, so
every frame the server sent the connection before has arrived. Absence checks
(``expect_none``) run after one; that works with any server that keeps the
order of one connection's frames, and needs no sleeping.

A server that does not read or does not answer at all gets one verdict, not a
table of failures (``liveness``): the runner asks before the first case, and
again after a case that failed without a word from the server
(``CaseResult.unanswered``); when the server does not answer, the run stops
there (``SuiteResult.verdict``). The whole run, this included, is bounded by
``run_timeout_s``.

Every wait is scaled to the server's measured round trip, and a case that
misses a wait is run once more with longer waits before it is called failed
(``pace``); a case that passed late is reported slow (``CaseResult.slow``).

With the server's rosauth secret (``RunOptions.auth_secret``, D23) every
connection sends a valid ``auth`` first, so the whole suite runs against a
secured server; cases marked ``authenticates`` send theirs themselves
(``send_auth``), and are skipped without the secret.
"""

from __future__ import annotations

import fnmatch
import itertools
import json
import secrets
import time
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import anyio
import cbor2

from rwt_client.connectors import Connection, ConnectionClosedError, connect
from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RemoteProtocolError, RwtError

from .bounds import (
    CASE_BUDGET_BYTES,
    CASE_TIMEOUT_S,
    MAX_FRAME_BYTES,
    RUN_TIMEOUT_S,
    SendTimeoutError,
    close_within,
    send_within,
)
from .detect import detect_dialect
from .frames import Received, auth_op, decode_frame
from .liveness import check_answers
from .match import JsonValue, describe, match, substitute
from .model import Case, Dialect, Profile, Requirement, Step, StepKind, Suite
from .pace import RETRY_BUDGET_S, RETRY_FACTOR, Pace, RoundTrips, Timing, waits_of
from .specdetect import SpecFinding, find_spec_version

if TYPE_CHECKING:
    import ssl
    from collections.abc import Callable

    from .versions import SpecVersion

__all__ = [
    "CaseResult",
    "Outcome",
    "RequirementResult",
    "RunOptions",
    "Slowness",
    "SuiteResult",
    "run_suite",
    "select",
]

NEEDS_SECRET = "needs --auth-secret-file (the server's rosauth secret)"
SYNC_ID = "rwt_conformance_sync"
SYNC_TYPE = "std_msgs/String"
_SYNC_RESEND_S = 0.5


class Outcome(StrEnum):
    """The result of a case or a requirement."""

    PASSED = "passed"
    FAILED = "failed"
    SKIPPED = "skipped"


@dataclass(frozen=True, slots=True)
class RunOptions:
    """How to run the suite.

    Attributes:
        url: the server, ``ws://HOST:PORT`` or ``tcp://HOST:PORT``.
        profile: what the server is held to (``Profile``).
        only: run only cases whose id, or one of whose requirement ids, matches
            one of these (shell-style patterns: ``D1*``).
        expect_timeout_s: default bound of one wait, seconds.
        case_timeout_s: bound of a whole case, seconds (``bounds.CASE_TIMEOUT_S``).
        run_timeout_s: bound of the whole run, seconds (``bounds.RUN_TIMEOUT_S``).
        max_frame_bytes: largest frame taken from the server, bytes; a bigger
            one closes its connection (``bounds.MAX_FRAME_BYTES``).
        case_budget_bytes: bytes of received frames a case may hold unconsumed,
            all its connections together; more fails the case
            (``bounds.CASE_BUDGET_BYTES``).
        auth_secret: the server's rosauth secret (D23), or None when the
            server does not authenticate.
        ssl_context: TLS settings for ``wss://`` and ``tcp+tls://`` (``--cafile``,
            ``--insecure``); the system's trusted authorities when None.
        dialect: the server's ROS edition; None asks the server first
            (``detect_dialect``).
        retry_budget_s: seconds the run may spend on retries of cases that
            missed a wait (``pace.RETRY_BUDGET_S``); 0: no retries.
        spec_version: the spec version the server is judged by (requirements
            outside it are skipped); None finds it first (``specdetect``).
    """

    url: str
    profile: Profile = Profile.STRICT
    only: tuple[str, ...] = ()
    expect_timeout_s: float = 3.0
    case_timeout_s: float = CASE_TIMEOUT_S
    run_timeout_s: float = RUN_TIMEOUT_S
    max_frame_bytes: int = MAX_FRAME_BYTES
    case_budget_bytes: int = CASE_BUDGET_BYTES
    auth_secret: str | None = field(default=None, repr=False)
    ssl_context: ssl.SSLContext | None = field(default=None, repr=False)
    dialect: Dialect | None = None
    retry_budget_s: float = RETRY_BUDGET_S
    spec_version: SpecVersion | None = None

    @property
    def transport(self) -> str:
        """``ws``, ``tcp`` or ``webrtc``, from the URL's scheme (its TLS forms included)."""
        scheme = urlsplit(self.url).scheme
        if scheme.startswith("webrtc+"):
            return "webrtc"
        return "tcp" if scheme in ("tcp", "tcp+tls") else "ws"


@dataclass(frozen=True, slots=True)
class Slowness:
    """Why a case that passed is reported slow (``pace``).

    Attributes:
        where: the step of its slowest wait, ``step 4 (expect on b)``; empty when
            the case waited for nothing.
        took_s: how long that wait took, seconds.
        nominal_s: the suite's wait for that step (``--timeout`` or its ``timeout_s``).
        first_try: None when the case passed at once, one of its waits over the
            suite's; else how its first try failed (it passed on its retry).
    """

    where: str
    took_s: float
    nominal_s: float
    first_try: str | None = None

    def describe(self) -> str:
        """One line: ``step 4 (expect on b) waited 4.21 s (the suite's wait: 3 s)``..."""
        waited = (
            f"{self.where} waited {self.took_s:.2f} s (the suite's wait: {self.nominal_s:g} s)"
            if self.where
            else ""
        )
        if self.first_try is None:
            return waited
        retry = f"passed on its retry, every wait {RETRY_FACTOR:g}x, after: {self.first_try}"
        return f"{retry}; its slowest wait then: {waited}" if waited else retry


@dataclass(frozen=True, slots=True)
class CaseResult:
    """What one case did: outcome, a one-line detail, seconds taken.

    ``unanswered``: the case failed without a word from the server (no frame on
    any of its connections, or a send the server did not take); the runner then
    asks whether the server answers at all (``liveness``).

    ``slow``: the case passed late (``Slowness``); None when it passed in the
    suite's waits, failed or was skipped. ``retried``: it ran a second time, every
    wait longer, after missing one (``pace``). ``missed_wait``: it failed because a
    wait (or a send, or the case's bound) ran out, which a retry may cure.
    ``off_version``: skipped because none of its requirements holds for the spec
    version the server is judged by (``Case.version_skip``).
    """

    case: Case
    outcome: Outcome
    detail: str = ""
    duration_s: float = 0.0
    unanswered: bool = False
    slow: Slowness | None = None
    retried: bool = False
    missed_wait: bool = False
    off_version: bool = False


@dataclass(frozen=True, slots=True)
class RequirementResult:
    """A requirement's outcome: failed if a case failed, passed if one passed."""

    requirement: Requirement
    outcome: Outcome
    detail: str
    cases: tuple[CaseResult, ...]


@dataclass(frozen=True, slots=True)
class SuiteResult:
    """Everything a run found; ``options.dialect`` is the dialect the cases spoke.

    ``verdict``: why the run stopped before its end (the server does not read or
    answer, or the run went over ``run_timeout_s``), one line; None when every
    selected case ran. A stopped run grades only the requirements of the cases
    that ran. ``timing``: the round trips measured and the retries (``pace``).
    ``spec``: the spec version the run judged by and where it came from; None
    when the run stopped before finding it.
    """

    options: RunOptions
    requirements: tuple[RequirementResult, ...]
    cases: tuple[CaseResult, ...]
    duration_s: float = 0.0
    verdict: str | None = None
    timing: Timing | None = None
    spec: SpecFinding | None = None

    def count(self, outcome: Outcome) -> int:
        """How many requirements ended with ``outcome``."""
        return sum(1 for r in self.requirements if r.outcome is outcome)

    @property
    def ok(self) -> bool:
        """True when the run ended and no requirement failed."""
        return self.verdict is None and self.count(Outcome.FAILED) == 0

    def summary(self) -> str:
        """``N passed, M failed, K skipped`` (requirements)."""
        return ", ".join(f"{self.count(o)} {o.value}" for o in Outcome)

    @property
    def slow(self) -> tuple[CaseResult, ...]:
        """The cases that passed late (``CaseResult.slow``)."""
        return tuple(c for c in self.cases if c.slow is not None)


class StepFailedError(RwtError):
    """A step's expectation did not hold; the text is the detail shown."""


class _MissedWaitError(StepFailedError):
    """A wait (or a send) ran out: the server may be slow rather than wrong (``pace``)."""


def select(suite: Suite, only: tuple[str, ...]) -> tuple[list[Requirement], list[Case]]:
    """Pick the requirements and cases an ``--only`` list names (all when empty)."""
    if not only:
        return list(suite.requirements.values()), list(suite.cases)

    def hit(name: str) -> bool:
        return any(fnmatch.fnmatchcase(name, pattern) for pattern in only)

    requirements = [r for r in suite.requirements.values() if hit(r.id)]
    chosen = {r.id for r in requirements}
    cases = [c for c in suite.cases if hit(c.id) or chosen.intersection(c.requirements)]
    named = {r for c in cases for r in c.requirements}
    requirements += [suite.requirements[r] for r in suite.requirements if r in named - chosen]
    return requirements, cases


async def run_suite(
    suite: Suite,
    options: RunOptions,
    *,
    on_case: Callable[[CaseResult], None] | None = None,
    on_dialect: Callable[[Dialect, str], None] | None = None,
) -> SuiteResult:
    """Check the server answers, then run the selected cases one after another and grade them.

    Args:
        suite: the loaded suite.
        options: server URL, profile, selection, time bounds.
        on_case: called after each case, for progress output.
        on_dialect: called with the dialect the server was found to speak and
            how (when ``options.dialect`` is None and the server answers).

    The spec version (``options.spec_version``, else found: ``specdetect``) is
    the result's ``spec``; a requirement outside it is skipped, and so is a case
    none of whose requirements holds for it (``Case.version_skip``).

    Returns:
        The results; never raises for what the server does. A server that
        cannot be reached, does not read or does not answer, and a run over
        ``options.run_timeout_s``, end the run with ``SuiteResult.verdict``.
    """
    started = time.monotonic()
    requirements, cases = select(suite, options.only)
    run = _SuiteRun(options, cases, on_case, on_dialect)
    with anyio.move_on_after(options.run_timeout_s) as scope:
        await run.execute()
    if scope.cancelled_caught:
        run.verdict = run.timed_out()
    if run.verdict is not None:  # graded: what ran
        ran = {r for c in run.results for r in c.case.requirements}
        requirements = [r for r in requirements if r.id in ran]
    version = run.options.spec_version
    graded = tuple(
        _grade(r, [c for c in run.results if r.id in c.case.requirements], version)
        for r in requirements
    )
    return SuiteResult(
        run.options,
        graded,
        tuple(run.results),
        time.monotonic() - started,
        run.verdict,
        run.timing(),
        run.spec,
    )


class _SuiteRun:
    """One run's progress: the cases done, the one under way, a verdict once stopped.

    It holds the run's pace (``pace``): the round trips measured, and the time
    its retries took.
    """

    def __init__(
        self,
        options: RunOptions,
        cases: list[Case],
        on_case: Callable[[CaseResult], None] | None,
        on_dialect: Callable[[Dialect, str], None] | None,
    ) -> None:
        self.options = options
        self.cases = cases
        self.on_case = on_case
        self.on_dialect = on_dialect
        self.results: list[CaseResult] = []
        self.current: Case | None = None
        self.verdict: str | None = None
        self.pace = Pace(RoundTrips())
        self.retries = 0
        self.retry_s = 0.0
        self.not_retried = 0
        self.spec: SpecFinding | None = None
        if options.spec_version is not None:
            self.spec = SpecFinding.given(options.spec_version)

    async def execute(self) -> None:
        self.verdict = await self._check_answers()
        if self.verdict is not None:
            return
        options = self.options
        if options.dialect is None:
            dialect, how = await detect_dialect(
                options.url,
                options.ssl_context,
                self.pace.wait_s(options.expect_timeout_s),
                options.auth_secret,
                options.max_frame_bytes,
            )
            self.options = options = replace(options, dialect=dialect)
            if self.on_dialect is not None:
                self.on_dialect(dialect, how)
        if self.spec is None:
            self.spec = await find_spec_version(
                options.url,
                options.dialect or Dialect.ROS2,
                options.ssl_context,
                self.pace.wait_s(options.expect_timeout_s),
                options.auth_secret,
                options.max_frame_bytes,
            )
            self.options = options = replace(options, spec_version=self.spec.version)
        run_id = secrets.token_hex(3)
        for index, case in enumerate(self.cases):
            self.current = case
            variables: dict[str, JsonValue] = {"ns": f"rwtc_{run_id}/c{index}", "run": run_id}
            result = await self._run(case, variables)
            self.results.append(result)
            if self.on_case is not None:
                self.on_case(result)
            if self.verdict is not None:
                return
        self.current = None

    async def _run(self, case: Case, variables: dict[str, JsonValue]) -> CaseResult:
        """Run ``case``, and once more with longer waits if it missed one (``pace``).

        Sets ``verdict`` when a try got no word from the server and it no longer
        answers at all.
        """
        first = await run_case(case, self.options, variables, self.pace)
        if not await self._still_answers(case, first):
            return first
        if first.outcome is not Outcome.FAILED or not first.missed_wait:
            return first
        if self.retry_s >= self.options.retry_budget_s:
            self.not_retried += 1
            spent = f" (not retried: retries took their {self.options.retry_budget_s:g} s)"
            return replace(first, detail=first.detail + spent)
        self.retries += 1
        retry = await run_case(
            case, self.options, {**variables, "ns": f"{variables['ns']}_retry"}, self.pace.retry()
        )
        self.retry_s += retry.duration_s
        await self._still_answers(case, retry)
        return _after_retry(first, retry)

    async def _still_answers(self, case: Case, result: CaseResult) -> bool:
        """After a try without a word from the server: whether it still answers (else a verdict)."""
        if not result.unanswered:
            return True
        problem = await self._check_answers()
        if problem is not None:
            self.verdict = f"the run stopped after case {case.id}: {problem}"
        return problem is None

    async def _check_answers(self) -> str | None:
        options = self.options
        return await check_answers(
            options.url,
            options.ssl_context,
            self.pace.wait_s(options.expect_timeout_s),
            options.auth_secret,
            options.max_frame_bytes,
            round_trips=self.pace.round_trips,
        )

    def timing(self) -> Timing:
        """The run's pace as it stands, for the reports."""
        return Timing.of(
            self.pace,
            self.options.expect_timeout_s,
            retries=self.retries,
            retry_s=self.retry_s,
            retry_budget_s=self.options.retry_budget_s,
            not_retried=self.not_retried,
        )

    def timed_out(self) -> str:
        """The verdict of a run cut by ``run_timeout_s``."""
        where = (
            f"in case {self.current.id}, {len(self.results)} of {len(self.cases)} cases done"
            if self.current is not None
            else "before the first case (checking the server, asking its dialect and spec version)"
        )
        return (
            f"the run took longer than {self.options.run_timeout_s:g} s (--run-timeout):"
            f" stopped {where}"
        )


def _after_retry(first: CaseResult, retry: CaseResult) -> CaseResult:
    """A case's result from its two tries: passed late (slow), or failed twice."""
    seconds = first.duration_s + retry.duration_s
    if retry.outcome is Outcome.PASSED:
        late = retry.slow or Slowness("", 0.0, 0.0)
        slow = replace(late, first_try=first.detail)
        return replace(retry, duration_s=seconds, slow=slow, retried=True)
    detail = f"{retry.detail} (also on its retry, every wait {RETRY_FACTOR:g}x)"
    return replace(retry, detail=detail, duration_s=seconds, retried=True)


AS_THE_REFERENCE = "as the reference does"
"""How a case's detail starts when it passed the reference's way (a recorded defect)."""


async def run_case(
    case: Case,
    options: RunOptions,
    variables: dict[str, JsonValue],
    pace: Pace | None = None,
) -> CaseResult:
    """Run one case (or skip it, saying why).

    A case recording a reference defect where it applies (``Step.defect``,
    docs/conformance.md) runs the spec's way first and, if that fails, the
    reference's way for each defect it cites, in order, on fresh connections
    and names (``${ns}`` gets ``_ref``, ``_ref1``...);
    it passes when either holds, its detail then ``as the reference does (REF
    §12.x)``. ``pace`` scales the waits (``pace``; None: the suite's waits, no
    round trip measured before).
    """
    if options.spec_version is not None:
        off = case.version_skip(options.spec_version)
        if off is not None:
            return CaseResult(case, Outcome.SKIPPED, off, off_version=True)
    reason = _skip_reason(case, options)
    if reason is not None:
        return CaseResult(case, Outcome.SKIPPED, reason)
    pace = pace or Pace(RoundTrips())
    defects = case.defects(options.profile, options.dialect or Dialect.ROS2)
    spec = await _run_way(case, options, variables, pace, reference_way=None)
    if not defects or spec.outcome is Outcome.PASSED:
        return spec
    seconds, details = spec.duration_s, [f"the spec's way: {spec.detail}"]
    unanswered, missed = spec.unanswered, spec.missed_wait
    for number, cited in enumerate(defects):
        ns = f"{variables['ns']}_ref{number or ''}"
        ref = await _run_way(case, options, {**variables, "ns": ns}, pace, reference_way=cited)
        seconds += ref.duration_s
        if ref.outcome is Outcome.PASSED:
            detail = f"{AS_THE_REFERENCE} ({cited}); the spec's way: {spec.detail}"
            return replace(ref, detail=detail, duration_s=seconds)
        details.append(f"the reference's way ({cited}): {ref.detail}")
        unanswered, missed = unanswered and ref.unanswered, missed or ref.missed_wait
    detail = "; ".join(details)
    return CaseResult(case, Outcome.FAILED, detail, seconds, unanswered, missed_wait=missed)


async def _run_way(
    case: Case,
    options: RunOptions,
    variables: dict[str, JsonValue],
    pace: Pace,
    *,
    reference_way: str | None,
) -> CaseResult:
    """Run the case's steps one way: the spec's (``None``: no ``defect`` step) or the reference's.

    The reference's way for the defect section ``reference_way`` leaves out the
    ``unless_defect`` steps and the steps of the case's other defects instead.
    """
    started = time.monotonic()
    run = _CaseRun(case, options, dict(variables), pace, reference_way=reference_way)
    dialect = options.dialect or Dialect.ROS2
    bound_s = pace.case_s(options.case_timeout_s, waits_of(case, options.profile, dialect))
    missed = False
    try:
        with anyio.fail_after(bound_s):
            await run.execute()
    except StepFailedError as exc:
        detail, missed = str(exc), isinstance(exc, _MissedWaitError)
    except TimeoutError:
        detail, missed = f"case timed out after {bound_s:g} s at step {run.step_number}", True
    except Exception as exc:  # a runner bug must not stop the suite
        detail = f"step {run.step_number}: runner error {type(exc).__name__}: {exc}"
        return CaseResult(case, Outcome.FAILED, detail, time.monotonic() - started)
    else:
        slow = run.slowest if run.slowest is not None and run.late(pace) else None
        return CaseResult(case, Outcome.PASSED, "", time.monotonic() - started, slow=slow)
    finally:
        await run.close_all()
    unanswered = run.send_blocked or not run.received
    seconds = time.monotonic() - started
    return CaseResult(case, Outcome.FAILED, detail, seconds, unanswered, missed_wait=missed)


def _skip_reason(case: Case, options: RunOptions) -> str | None:
    if case.pending is not None:
        return f"pending: {case.pending}"
    reason = case.skip_reason(options.profile, options.dialect or Dialect.ROS2)
    if reason is not None:
        return reason
    if options.transport not in case.transports:
        return f"needs {'/'.join(sorted(case.transports))}"
    if case.authenticates and options.auth_secret is None:
        return NEEDS_SECRET
    return None


def _grade(
    requirement: Requirement, results: list[CaseResult], version: SpecVersion | None = None
) -> RequirementResult:
    if version is not None and not requirement.versions.holds(version):
        detail = f"holds for {requirement.versions}; the server is judged by {version.label}"
        return RequirementResult(requirement, Outcome.SKIPPED, detail, tuple(results))
    failed = [r for r in results if r.outcome is Outcome.FAILED]
    passed = [r for r in results if r.outcome is Outcome.PASSED]
    if failed:
        outcome, detail = Outcome.FAILED, f"{failed[0].case.id}: {failed[0].detail}"
    elif passed:
        slow = sum(1 for r in passed if r.slow is not None)
        late = f" ({slow} slow)" if slow else ""
        outcome, detail = Outcome.PASSED, f"{len(passed)} case{'s' * (len(passed) > 1)}{late}"
    elif results:
        outcome, detail = Outcome.SKIPPED, results[0].detail
    else:
        outcome, detail = Outcome.SKIPPED, "no case selected"
    return RequirementResult(requirement, outcome, detail, tuple(results))


@dataclass
class _Link:
    """One connection of a case and what it has received so far."""

    name: str
    conn: Connection
    sync_topic: str
    frames: list[Received] = field(default_factory=list)
    arrived: anyio.Event = field(default_factory=anyio.Event)
    tokens: set[str] = field(default_factory=set)
    sync_ready: bool = False
    closed_reason: str | None = None
    fragments: dict[str | int, list[Received]] = field(default_factory=dict)
    kept_bytes: int = 0
    """Bytes of ``frames`` (``Received.size``), counted against the case's budget."""

    def drop(self, received: Received) -> None:
        """Forget a kept frame: consumed by an ``expect``, or a joined sync echo."""
        self.kept_bytes -= received.size

    def notify(self) -> None:
        self.arrived.set()
        self.arrived = anyio.Event()


class _CaseRun:
    def __init__(
        self,
        case: Case,
        options: RunOptions,
        variables: dict[str, JsonValue],
        pace: Pace | None = None,
        *,
        reference_way: str | None = None,
    ) -> None:
        self.case = case
        self.reference_way = reference_way
        self.options = options
        self.variables = variables
        self.pace = pace or Pace(RoundTrips())
        self.links: dict[str, _Link] = {}
        self.step_number = 0
        self.where = ""
        """The step under way, ``step 4 (expect on b)``."""
        self.slowest: Slowness | None = None
        """The wait that took longest beyond the suite's wait for it."""
        self._tokens = itertools.count(1)
        self._tasks: anyio.abc.TaskGroup | None = None
        self._violation: str | None = None
        self.received = False
        """Whether any frame came from the server, on any connection."""
        self.send_blocked = False
        """Whether a send timed out (``bounds.SendTimeoutError``)."""

    async def execute(self) -> None:
        failure: StepFailedError | None = None
        async with anyio.create_task_group() as tasks:
            self._tasks = tasks
            try:
                await self._steps()
            except StepFailedError as exc:  # raised after the task group, not wrapped in a group
                failure = exc
            tasks.cancel_scope.cancel()
        if self._violation is not None:  # what the server did stopped the steps
            step = self.case.steps[self.step_number - 1] if self.step_number else None
            where = f"step {self.step_number} ({step.kind.value} on {step.on})" if step else ""
            raise StepFailedError(f"{where}: {self._violation}".lstrip(": "))
        if failure is not None:
            raise failure

    def _violated(self, link: _Link, reason: str) -> None:
        """Stop the case: the server broke one of the runner's bounds (``bounds``)."""
        if self._violation is None:
            self._violation = f"connection {link.name}: {reason}"
        assert self._tasks is not None
        self._tasks.cancel_scope.cancel()

    async def _steps(self) -> None:
        for number, step in enumerate(self.case.steps, start=1):
            self.step_number = number
            if not step.runs_in(self.options.profile, self.options.dialect or Dialect.ROS2):
                continue
            if self.reference_way is None:
                if step.defect is not None:
                    continue
            elif step.unless_defect or step.defect not in (None, self.reference_way):
                continue
            where = self.where = f"step {number} ({step.kind.value} on {step.on})"
            try:
                for repetition in range(step.repeat):
                    if repetition and step.pace_s:
                        await anyio.sleep(step.pace_s)
                    self.variables["i"] = repetition
                    await self._run_step(step)
            except StepFailedError as exc:  # a missed wait stays one (``pace``)
                raise type(exc)(f"{where}: {exc}") from None
            except ConnectionClosedError as exc:
                raise StepFailedError(f"{where}: {exc.message}") from None
            except SendTimeoutError as exc:
                self.send_blocked = True
                raise _MissedWaitError(f"{where}: {exc}") from None

    def late(self, pace: Pace) -> bool:
        """Whether a try that passed is slow: a wait over the suite's, or a retry (``pace``)."""
        slowest = self.slowest
        over = slowest is not None and slowest.took_s > slowest.nominal_s
        return over or pace.factor > 1

    def _waited(self, started: float, nominal_s: float) -> None:
        """Note a wait that ended as it should, begun at ``started`` (``time.monotonic``)."""
        took_s = time.monotonic() - started
        slowest = self.slowest
        if slowest is None or took_s - nominal_s > slowest.took_s - slowest.nominal_s:
            self.slowest = Slowness(self.where, took_s, nominal_s)

    async def close_all(self) -> None:
        """Close every connection, each within ``bounds.CLOSE_TIMEOUT_S`` (shielded)."""
        for link in self.links.values():
            await close_within(link.conn)

    async def _run_step(self, step: Step) -> None:
        if step.kind is StepKind.CLOSE:
            link = self.links.get(step.on)
            if link is not None:
                await close_within(link.conn)
            return
        link = await self._link(step.on)
        nominal_s = step.timeout_s or self.options.expect_timeout_s
        timeout_s = self.pace.wait_s(nominal_s)
        kind = step.kind
        if kind in _SENDS or kind is StepKind.SEND_AUTH:
            if kind is StepKind.SEND_AUTH:
                frame: str | bytes = json.dumps(self._auth_op(step.value))
            else:
                frame = _SENDS[kind](self._sub(step.value))
            try:
                await send_within(link.conn, frame, timeout_s)
            except ConnectionClosedError as exc:  # later steps say whether closing was right
                link.closed_reason = link.closed_reason or exc.message
                link.notify()
        elif kind in (StepKind.EXPECT, StepKind.EXPECT_STATUS):
            pattern = self._sub(step.value)
            if kind is StepKind.EXPECT_STATUS and isinstance(pattern, dict):
                pattern = {"op": "status", **pattern}
            for _ in range(step.count):
                started = time.monotonic()
                await self._expect(link, pattern, step, timeout_s)
                self._waited(started, nominal_s)
        elif kind in (StepKind.EXPECT_NONE, StepKind.SYNC):
            started = time.monotonic()
            await self._sync(link, timeout_s)
            self._waited(started, nominal_s)
            if kind is StepKind.EXPECT_NONE:
                self._expect_none(link, self._sub(step.value))
        elif kind is StepKind.EXPECT_CLOSED:
            started = time.monotonic()
            await self._expect_closed(link, timeout_s)
            self._waited(started, nominal_s)

    async def _expect_closed(self, link: _Link, timeout_s: float) -> None:
        with anyio.move_on_after(timeout_s):
            while link.closed_reason is None:
                await link.arrived.wait()
        if link.closed_reason is None:
            raise _MissedWaitError(f"the server kept the connection open for {timeout_s:g} s")

    def _sub(self, value: object) -> JsonValue:
        try:
            return substitute(value, self.variables)
        except KeyError as exc:
            raise StepFailedError(f"variable {exc} was never captured") from None

    async def _link(self, name: str) -> _Link:
        link = self.links.get(name)
        if link is None:
            wait_s = self.pace.wait_s(self.options.expect_timeout_s)
            try:
                conn = await connect(
                    self.options.url,
                    timeout_s=2 * wait_s,
                    max_message_size=self.options.max_frame_bytes,
                    ssl_context=self.options.ssl_context,
                )
            except TimeoutError:
                raise _MissedWaitError(f"connecting took over {2 * wait_s:g} s") from None
            if self.options.auth_secret is not None and not self.case.authenticates:
                auth = json.dumps(self._auth_op({}))
                await send_within(conn, auth, wait_s)
            topic = f"/{self.variables['ns']}/sync_{name}"
            link = self.links[name] = _Link(name, conn, topic)
            assert self._tasks is not None
            self._tasks.start_soon(self._read, link)
        return link

    async def _read(self, link: _Link) -> None:
        try:
            while True:
                frame = await link.conn.receive()
                self.received = True
                received = decode_frame(frame)
                if received.problem is not None:
                    self._violated(link, received.problem)
                    return
                if not self._hidden(link, received.value):
                    self._keep(link, received)
                    self._defragment(link, received)
                link.notify()
        except ConnectionClosedError as exc:
            link.closed_reason = exc.message
            link.notify()

    def _keep(self, link: _Link, received: Received) -> None:
        """Keep a frame for the steps, within the case's byte budget."""
        budget = self.options.case_budget_bytes
        if sum(other.kept_bytes for other in self.links.values()) + received.size > budget:
            self._violated(
                link,
                f"the server sent more than {budget} bytes the case did not consume"
                " (the case's budget, --case-budget-bytes)",
            )
            return
        link.frames.append(received)
        link.kept_bytes += received.size

    def _hidden(self, link: _Link, value: JsonValue) -> bool:
        if not isinstance(value, dict):
            return False
        if value.get("op") == "status" and (
            self.options.profile is Profile.REFERENCE or value.get("id") == SYNC_ID
        ):
            return True
        if value.get("op") == "publish" and value.get("topic") == link.sync_topic:
            msg = value.get("msg")
            if isinstance(msg, dict) and isinstance(msg.get("data"), str):
                link.tokens.add(msg["data"])
            return True
        return False

    def _defragment(self, link: _Link, received: Received) -> None:
        """Join outgoing ``fragment`` ops, so a sync works through fragmentation.

        rosbridge_suite applies a ``fragment_size`` given on any op to all
        later output of the connection (docs/reference-behaviour.md REF §1.3),
        sync echoes included. Parts are joined by ``num`` once they parse; a
        joined sync echo counts as one and its parts are taken out of the
        frames a case sees. Parts of one id restart at ``num`` 0.
        """
        value = received.value
        if not isinstance(value, dict) or value.get("op") != "fragment":
            return
        key, num, data = value.get("id"), value.get("num"), value.get("data")
        # the id is the server's: kept as it came (``str`` of an int of 5,000 digits
        # raises), and only a string or an integer can name a message's parts
        if not isinstance(key, str | int) or isinstance(key, bool):
            return
        if not isinstance(num, int) or not isinstance(data, str):
            return
        parts = link.fragments.setdefault(key, [])
        if num == 0:
            parts.clear()
        parts.append(received)
        try:
            joined = decode_json_text(
                "".join(_fragment_data(p) for p in sorted(parts, key=_fragment_num)), "fragments"
            )
        except RemoteProtocolError:
            return
        del link.fragments[key]
        if self._hidden(link, joined):
            for part in parts:
                if any(f is part for f in link.frames):
                    link.drop(part)
            link.frames[:] = [f for f in link.frames if not any(f is p for p in parts)]

    async def _expect(self, link: _Link, pattern: JsonValue, step: Step, timeout_s: float) -> None:
        with anyio.move_on_after(timeout_s):
            while True:
                for index, received in enumerate(link.frames):
                    if step.binary is not None and step.binary is not received.binary:
                        continue
                    problem = match(pattern, received.value, self.variables)
                    if problem is None:
                        link.drop(link.frames.pop(index))
                        return
                    if step.in_order and _same_stream(pattern, received.value):
                        raise StepFailedError(
                            f"out of order: {describe(received.value, 100)} ({problem})"
                        )
                if link.closed_reason is not None:
                    raise StepFailedError(
                        f"connection closed ({link.closed_reason}) before {describe(pattern, 120)}"
                    )
                await link.arrived.wait()
        near = self._near(link, pattern, step)
        raise _MissedWaitError(
            f"no frame matching {describe(pattern, 160)} within {timeout_s:g} s{near}"
        )

    def _near(self, link: _Link, pattern: JsonValue, step: Step) -> str:
        if not link.frames:
            return "; nothing else received"
        op = pattern.get("op") if isinstance(pattern, dict) else None
        same = [f for f in link.frames if isinstance(f.value, dict) and f.value.get("op") == op]
        shown = same[-2:] or link.frames[-2:]
        kind = "CBOR" if step.binary else "JSON text"
        notes = [match(pattern, f.value, {}) or f"matches but is not {kind}" for f in shown]
        return "; received " + "; ".join(
            f"{describe(f.value, 100)} ({n})" for f, n in zip(shown, notes, strict=True)
        )

    def _auth_op(self, fields: object) -> dict[str, JsonValue]:
        secret = self.options.auth_secret
        if secret is None:  # only authenticating cases send auth, and they need the secret
            raise StepFailedError("send_auth needs the server's secret")
        given = self._sub(fields)
        try:
            return auth_op(
                secret,
                given if isinstance(given, dict) else {},
                urlsplit(self.options.url).hostname or "",
            )
        except ValueError as exc:
            raise StepFailedError(f"send_auth: {exc}") from None

    def _expect_none(self, link: _Link, pattern: JsonValue) -> None:
        for received in link.frames:
            if match(pattern, received.value, {}) is None:
                raise StepFailedError(f"unexpected {describe(received.value, 160)}")

    async def _sync(self, link: _Link, timeout_s: float) -> None:
        if link.closed_reason is not None:
            raise StepFailedError(f"cannot sync: connection closed ({link.closed_reason})")
        if not link.sync_ready:
            base = {"topic": link.sync_topic, "type": SYNC_TYPE, "id": SYNC_ID}
            await send_within(link.conn, json.dumps({"op": "subscribe", **base}), timeout_s)
            await send_within(link.conn, json.dumps({"op": "advertise", **base}), timeout_s)
            link.sync_ready = True
        # each send has its token (``sync-3.0``, its resend ``sync-3.1``): the echo says
        # which send it answers, so its round trip is measured without doubt (as TCP's
        # timestamps, RFC 7323 §4), setting up the subscription left out (``pace``)
        number, sent = next(self._tokens), dict[str, float]()
        with anyio.move_on_after(timeout_s):
            while not (echoed := sent.keys() & link.tokens):
                token = f"sync-{number}.{len(sent)}"
                publish = {"op": "publish", "topic": link.sync_topic, "msg": {"data": token}}
                await send_within(link.conn, json.dumps({**publish, "id": SYNC_ID}), timeout_s)
                sent[token] = time.monotonic()
                with anyio.move_on_after(_SYNC_RESEND_S):
                    while not sent.keys() & link.tokens:
                        if link.closed_reason is not None:
                            raise StepFailedError(
                                f"connection closed ({link.closed_reason}) during sync"
                            )
                        await link.arrived.wait()
            self.pace.round_trips.add(time.monotonic() - max(sent[t] for t in echoed))
            return
        raise _MissedWaitError(
            f"sync: the server did not echo a publish on {link.sync_topic} within {timeout_s:g} s"
        )


_SENDS: dict[StepKind, Callable[[JsonValue], str | bytes]] = {
    StepKind.SEND: json.dumps,
    StepKind.SEND_RAW: str,
    StepKind.SEND_BINARY: cbor2.dumps,
}


def _fragment_num(part: Received) -> int:
    value = part.value
    return value["num"] if isinstance(value, dict) and isinstance(value.get("num"), int) else 0


def _fragment_data(part: Received) -> str:
    value = part.value
    return value["data"] if isinstance(value, dict) and isinstance(value.get("data"), str) else ""


def _same_stream(pattern: JsonValue, value: JsonValue) -> bool:
    """Whether ``value`` has the ``op`` and ``topic`` of ``pattern``."""
    if not isinstance(pattern, dict) or not isinstance(value, dict):
        return False
    return all(value.get(key) == pattern.get(key) for key in ("op", "topic") if key in pattern)
