"""The conformance suite: requirements and cases as data, and a runner (``rwt conformance``).

Usage from Python::

    import anyio
    from rwt_conformance import RunOptions, load_suite, run_suite

    result = anyio.run(run_suite, load_suite(), RunOptions("ws://127.0.0.1:9090"))
    print(result.summary())
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .model import Case, Profile, Requirement, Suite, SuiteError, load_suite

if TYPE_CHECKING:
    from .runner import (
        CaseResult,
        Outcome,
        RequirementResult,
        RunOptions,
        Slowness,
        SuiteResult,
        run_suite,
    )

__all__ = [
    "Case",
    "CaseResult",
    "Outcome",
    "Profile",
    "Requirement",
    "RequirementResult",
    "RunOptions",
    "Slowness",
    "Suite",
    "SuiteError",
    "SuiteResult",
    "load_suite",
    "run_suite",
]

_RUNNER_NAMES = frozenset(
    (
        "CaseResult",
        "Outcome",
        "RequirementResult",
        "RunOptions",
        "Slowness",
        "SuiteResult",
        "run_suite",
    )
)


def __getattr__(name: str) -> object:
    # The runner (connectors, cbor2) loads on first use, not with ``rwt serve``,
    # whose command line registers ``rwt conformance`` beside it (benchmarks B11).
    if name in _RUNNER_NAMES:
        from . import runner  # noqa: PLC0415

        return getattr(runner, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
