"""Reports of a conformance run: a rich table, JUnit XML and JSON."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from .runner import Outcome, SuiteResult

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["print_table", "write_json", "write_junit"]

_STYLE = {Outcome.PASSED: "green", Outcome.FAILED: "bold red", Outcome.SKIPPED: "yellow"}


def print_table(result: SuiteResult, console: Console | None = None) -> None:
    """Print one row per requirement (id, section, result, detail), then the summary line.

    A run that stopped early (``SuiteResult.verdict``) shows the requirements of
    the cases that ran; the command line prints the verdict itself.
    """
    console = console or Console()
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
    console.print(f"{result.summary()} ({len(result.cases)} cases in {result.duration_s:.1f} s)")


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
        lines = [f"{c.case.id}: {c.outcome.value} {c.detail}".rstrip() for c in row.cases]
        ET.SubElement(element, "system-out").text = "\n".join(lines)
    root = ET.Element("testsuites")
    root.append(suite)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def write_json(result: SuiteResult, path: Path) -> None:
    """Write the run as JSON: options, summary, the verdict, requirements with their cases.

    ``verdict`` is null, or why the run stopped early (``SuiteResult.verdict``).
    """
    document = {
        "url": result.options.url,
        "profile": result.options.profile.value,
        "summary": {o.value: result.count(o) for o in Outcome},
        "verdict": result.verdict,
        "duration_s": round(result.duration_s, 3),
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
                    }
                    for c in row.cases
                ],
            }
            for row in result.requirements
        ],
    }
    path.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
