"""Reports of a conformance run: a rich table, JUnit XML and JSON.

Each says how the run was paced (``pace``): the server's round trip, what it
added to the waits, the retries, and which cases passed late (slow) and why;
and which spec version it judged by, and where that came from (``specdetect``).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from .runner import CaseResult, Outcome, Slowness, SuiteResult

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["print_table", "write_json", "write_junit"]

_STYLE = {Outcome.PASSED: "green", Outcome.FAILED: "bold red", Outcome.SKIPPED: "yellow"}


def print_table(result: SuiteResult, console: Console | None = None) -> None:
    """Print the spec version, a row per requirement, the slow cases, the pace, the summary.

    The first line is ``spec version 2.1.0 (from GET /version)`` (``SpecFinding``);
    a row has the requirement's id, section, result and detail.

    A run that stopped early (``SuiteResult.verdict``) shows the requirements of
    the cases that ran; the command line prints the verdict itself.
    """
    console = console or Console()
    if result.spec is not None:
        console.print(result.spec.describe(), markup=False, soft_wrap=True)  # one line
    table = Table(
        title=f"rosbridge conformance: {result.options.url} ({result.options.profile.value})"
    )
    table.add_column("id", no_wrap=True)
    table.add_column("section", no_wrap=True)
    table.add_column("result", no_wrap=True)
    table.add_column("detail", overflow="fold")
    for row in result.requirements:
        style = _STYLE[row.outcome]
        table.add_row(
            row.requirement.id, row.requirement.source, f"[{style}]{row.outcome.value}", row.detail
        )
    console.print(table)
    for case in result.slow:
        assert case.slow is not None
        console.print(f"slow: {case.case.id}: {case.slow.describe()}", markup=False)
    if result.timing is not None:
        console.print(f"pace: {result.timing.describe()}", markup=False)
    slow = f"; {len(result.slow)} slow" if result.slow else ""
    console.print(
        f"{result.summary()} ({len(result.cases)} cases in {result.duration_s:.1f} s{slow})",
        markup=False,
    )


def write_junit(result: SuiteResult, path: Path) -> None:
    """Write JUnit XML: one test case per requirement, its cases in the system output.

    A run that stopped early (``SuiteResult.verdict``) adds a test case ``run``
    whose ``error`` is the verdict.
    """
    suite = ET.Element(
        "testsuite",
        name="rwt-conformance",
        tests=str(len(result.requirements) + (result.verdict is not None)),
        failures=str(result.count(Outcome.FAILED)),
        errors=str(int(result.verdict is not None)),
        skipped=str(result.count(Outcome.SKIPPED)),
        time=f"{result.duration_s:.3f}",
    )
    found: dict[str, object] = {}
    if result.spec is not None:
        found["spec_version"] = result.spec.as_json()
    found.update(_timing(result) or {})
    if found:
        properties = ET.SubElement(suite, "properties")
        for name, value in found.items():
            ET.SubElement(properties, "property", name=name, value=json.dumps(value))
    if result.verdict is not None:
        element = ET.SubElement(suite, "testcase", classname="rwt-conformance", name="run")
        ET.SubElement(element, "error", message=result.verdict)
    for row in result.requirements:
        seconds = sum(c.duration_s for c in row.cases)
        element = ET.SubElement(
            suite,
            "testcase",
            classname=row.requirement.source,
            name=row.requirement.id,
            time=f"{seconds:.3f}",
        )
        if row.outcome is Outcome.FAILED:
            ET.SubElement(element, "failure", message=row.detail).text = row.requirement.statement
        elif row.outcome is Outcome.SKIPPED:
            ET.SubElement(element, "skipped", message=row.detail)
        lines = [_case_line(c) for c in row.cases]
        ET.SubElement(element, "system-out").text = "\n".join(lines)
    root = ET.Element("testsuites")
    root.append(suite)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def write_json(result: SuiteResult, path: Path) -> None:
    """Write the run as JSON: options, the spec version, summary, verdict, pace, requirements.

    ``spec_version`` is ``{"version", "source", "detail"}`` (``SpecFinding``; source
    ``version-endpoint``, ``probe`` or ``option``), null for a run stopped first.
    ``verdict`` is null, or why the run stopped early (``SuiteResult.verdict``).
    ``timing`` is the run's pace (docs/conformance.md lists its fields); each case
    has ``slow`` (null, or why it passed late) and ``retried``.
    """
    document = {
        "url": result.options.url,
        "profile": result.options.profile.value,
        "spec_version": None if result.spec is None else result.spec.as_json(),
        "summary": {o.value: result.count(o) for o in Outcome},
        "slow_cases": len(result.slow),
        "verdict": result.verdict,
        "duration_s": round(result.duration_s, 3),
        "timing": _timing(result),
        "requirements": [
            {
                "id": row.requirement.id,
                "source": row.requirement.source,
                "statement": row.requirement.statement,
                "result": row.outcome.value,
                "detail": row.detail,
                "cases": [
                    {
                        "id": c.case.id,
                        "result": c.outcome.value,
                        "detail": c.detail,
                        "duration_s": round(c.duration_s, 3),
                        "retried": c.retried,
                        "slow": _slowness(c.slow),
                    }
                    for c in row.cases
                ],
            }
            for row in result.requirements
        ],
    }
    path.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")


def _case_line(case: CaseResult) -> str:
    """``id: outcome detail``, and why it was slow."""
    line = f"{case.case.id}: {case.outcome.value} {case.detail}".rstrip()
    return line if case.slow is None else f"{line} (slow: {case.slow.describe()})"


def _slowness(slow: Slowness | None) -> dict[str, object] | None:
    if slow is None:
        return None
    return {
        "step": slow.where,
        "took_s": round(slow.took_s, 3),
        "nominal_s": slow.nominal_s,
        "first_try": slow.first_try,
        "text": slow.describe(),
    }


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


def _timing(result: SuiteResult) -> dict[str, object] | None:
    """The run's pace (``pace.Timing``), in seconds, or None."""
    timing = result.timing
    if timing is None:
        return None
    return {
        "round_trip_s": {
            "samples": timing.samples,
            "first": _round(timing.first_s),
            "smoothed": _round(timing.smoothed_s),
            "max": _round(timing.max_s),
        },
        "nominal_wait_s": timing.nominal_wait_s,
        "extra_wait_s": _round(timing.extra_wait_s),
        "retries": timing.retries,
        "retry_s": _round(timing.retry_s),
        "retry_budget_s": timing.retry_budget_s,
        "not_retried": timing.not_retried,
    }
