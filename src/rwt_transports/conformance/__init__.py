"""The conformance suite: requirements and cases as data, and a runner (``rwt conformance``).

Usage from Python::

    import anyio
    from rwt_transports.conformance import RunOptions, load_suite, run_suite

    result = anyio.run(run_suite, load_suite(), RunOptions("ws://127.0.0.1:9090"))
    print(result.summary())
"""

from __future__ import annotations

from .model import Case, Profile, Requirement, Suite, SuiteError, load_suite
from .runner import CaseResult, Outcome, RequirementResult, RunOptions, SuiteResult, run_suite

__all__ = [
    "Case",
    "CaseResult",
    "Outcome",
    "Profile",
    "Requirement",
    "RequirementResult",
    "RunOptions",
    "Suite",
    "SuiteError",
    "SuiteResult",
    "load_suite",
    "run_suite",
]
