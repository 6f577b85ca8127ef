"""How long the runner waits for a server: the suite's waits, scaled to its measured round trip.

The suite's waits (``--timeout``, a step's ``timeout_s``, ``--case-timeout``)
are what a server that answers at once needs. A server on a loaded machine, or
far away, answers later, and a fixed wait would give the same server a
different verdict on a busy CI runner than on an idle desk
(docs/conformance.md, "Slow servers and loaded machines"). So the runner:

- measures the server's round trip at the start (the time to the liveness
  check's first answer) and all through the run (each ``sync`` of a case: a
  publish echoed on a private topic, each send its own token), and keeps an
  estimate as TCP keeps its
  retransmission timeout (RFC 6298 §2: a smoothed round trip SRTT, its
  variation RTTVAR, and RTO = SRTT + 4 RTTVAR);
- adds ``ROUND_TRIPS_PER_WAIT`` RTOs (at most ``MAX_EXTRA_WAIT_S``) to every
  wait, and as much again for every wait of a case to the case's bound;
- runs a case that still misses a wait once more, every wait ``RETRY_FACTOR``
  times as long, before calling it failed; a case that then passes is
  reported slow. Once the run's retries took ``--retry-budget`` seconds
  (``RETRY_BUDGET_S``) no case is retried again, and the whole run stays within
  ``--run-timeout``.

A case is slow when it passed but one of its waits took longer than the
suite's wait for it (the scaled wait took it), or when it passed on its retry.
"""

from __future__ import annotations

from dataclasses import dataclass

from .model import Case, Dialect, Profile, StepKind

__all__ = [
    "MAX_EXTRA_WAIT_S",
    "RETRY_BUDGET_S",
    "RETRY_FACTOR",
    "ROUND_TRIPS_PER_WAIT",
    "Pace",
    "RoundTrips",
    "Timing",
    "waits_of",
]

ROUND_TRIPS_PER_WAIT = 2
"""RTOs added to each wait: an expected frame often answers a frame that itself
went through the server first (a call to a provider and its response)."""

MAX_EXTRA_WAIT_S = 30.0
"""Most seconds the measured round trip adds to one wait: a server whose round trip
grows without end cannot stretch every wait with it (the run is capped too)."""

RETRY_FACTOR = 3.0
"""How many times longer every wait (and the case's bound) is on a case's retry."""

RETRY_BUDGET_S = 120.0
"""Seconds of retries after which a run retries no more (``--retry-budget``): a case
that misses a wait then fails without one. A server failing many cases by their waits is
more likely wrong than slow, and must not take the run past its bound."""

_ALPHA = 1 / 8  # RFC 6298 §2.3
_BETA = 1 / 4
_K = 4


class RoundTrips:
    """The server's round trip, estimated as RFC 6298 §2 estimates TCP's (seconds).

    No clock granularity term and no 1 s minimum (the RFC's, for retransmissions
    on a network): a local server's round trip is a millisecond.

    Attributes:
        samples: how many round trips were measured.
        first_s: the first one (the liveness check's), None before it.
        max_s: the longest one.
        srtt_s: the smoothed round trip, None before the first.
        rttvar_s: its variation.
    """

    def __init__(self) -> None:
        self.samples = 0
        self.first_s: float | None = None
        self.max_s = 0.0
        self.srtt_s: float | None = None
        self.rttvar_s = 0.0

    def add(self, seconds: float) -> None:
        """Take one measured round trip into the estimate (RFC 6298 §2.2, §2.3)."""
        seconds = max(seconds, 0.0)
        self.samples += 1
        self.max_s = max(self.max_s, seconds)
        if self.srtt_s is None:
            self.first_s = seconds
            self.srtt_s, self.rttvar_s = seconds, seconds / 2
            return
        self.rttvar_s = (1 - _BETA) * self.rttvar_s + _BETA * abs(self.srtt_s - seconds)
        self.srtt_s = (1 - _ALPHA) * self.srtt_s + _ALPHA * seconds

    @property
    def rto_s(self) -> float:
        """SRTT + 4 RTTVAR, seconds; 0 before the first sample."""
        return 0.0 if self.srtt_s is None else self.srtt_s + _K * self.rttvar_s


@dataclass(frozen=True, slots=True)
class Pace:
    """The waits of one try of a case: nominal waits plus the round trip's share.

    Attributes:
        round_trips: the run's estimate, shared by every case (and still measuring).
        factor: 1 on a first try, ``RETRY_FACTOR`` on a retry.
    """

    round_trips: RoundTrips
    factor: float = 1.0

    @property
    def extra_s(self) -> float:
        """Seconds the round trip adds to one wait now (``ROUND_TRIPS_PER_WAIT`` RTOs, capped)."""
        return min(ROUND_TRIPS_PER_WAIT * self.round_trips.rto_s, MAX_EXTRA_WAIT_S)

    def wait_s(self, nominal_s: float) -> float:
        """The bound of one wait (or send) whose suite value is ``nominal_s`` seconds.

        Rounded to 10 ms, as reports show it (``within 9.03 s``).
        """
        return round((nominal_s + self.extra_s) * self.factor, 2)

    def case_s(self, nominal_s: float, waits: int) -> float:
        """The bound of a case of ``waits`` waits whose suite value is ``nominal_s`` (10 ms)."""
        return round((nominal_s + waits * self.extra_s) * self.factor, 2)

    def retry(self) -> Pace:
        """The pace of a retry: the same estimate, every wait ``RETRY_FACTOR`` times longer."""
        return Pace(self.round_trips, RETRY_FACTOR)


@dataclass(frozen=True, slots=True)
class Timing:
    """How a run's waits were paced, for its reports (``SuiteResult.timing``); seconds.

    Attributes:
        nominal_wait_s: the suite's wait (``--timeout``).
        samples: round trips measured.
        first_s: the first (the liveness check's); None without any.
        smoothed_s: SRTT at the end; None without any.
        max_s: the longest.
        extra_wait_s: what the round trip added to each wait at the end.
        retries: cases run a second time after missing a wait.
        retry_s: seconds the retries took.
        retry_budget_s: the most they could take (``--retry-budget``).
        not_retried: cases that missed a wait and were not retried (the budget spent).
    """

    nominal_wait_s: float
    samples: int
    first_s: float | None
    smoothed_s: float | None
    max_s: float
    extra_wait_s: float
    retries: int = 0
    retry_s: float = 0.0
    retry_budget_s: float = RETRY_BUDGET_S
    not_retried: int = 0

    @classmethod
    def of(
        cls,
        pace: Pace,
        nominal_wait_s: float,
        *,
        retries: int,
        retry_s: float,
        retry_budget_s: float,
        not_retried: int,
    ) -> Timing:
        """The report of ``pace``'s estimate as it stands, and of the run's retries."""
        trips = pace.round_trips
        return cls(
            nominal_wait_s,
            trips.samples,
            trips.first_s,
            trips.srtt_s,
            trips.max_s,
            pace.extra_s,
            retries,
            retry_s,
            retry_budget_s,
            not_retried,
        )

    def describe(self) -> str:
        """One line: the round trip, what it added to the waits, the retries."""
        if self.smoothed_s is None:
            trip = "round trip not measured"
        else:
            trip = (
                f"round trip {self.smoothed_s:.3f} s (smoothed; first {self.first_s or 0:.3f} s,"
                f" longest {self.max_s:.3f} s, {self.samples} measured):"
                f" each wait {self.nominal_wait_s:g} s + {self.extra_wait_s:.2f} s"
            )
        retried = (
            f"{self.retries} case{'s' * (self.retries != 1)} retried"
            f" ({self.retry_s:.1f} s of the {self.retry_budget_s:g} s budget)"
        )
        left = f", {self.not_retried} not retried (budget spent)" if self.not_retried else ""
        return f"{trip}; {retried}{left}"


_WAITING = frozenset(
    (
        StepKind.EXPECT,
        StepKind.EXPECT_STATUS,
        StepKind.EXPECT_NONE,
        StepKind.EXPECT_CLOSED,
        StepKind.SYNC,
    )
)


def waits_of(case: Case, profile: Profile, dialect: Dialect) -> int:
    """How many round trips a case waits for: its waiting steps and its connections."""
    steps = [step for step in case.steps if step.runs_in(profile, dialect)]
    waits = sum(
        (step.count if step.kind in (StepKind.EXPECT, StepKind.EXPECT_STATUS) else 1) * step.repeat
        for step in steps
        if step.kind in _WAITING
    )
    return waits + len({step.on for step in steps})
