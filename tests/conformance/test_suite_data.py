"""The suite's data: every requirement has a case, every case names requirements."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from rwt_conformance.model import TRANSPORTS, SuiteError, load_suite
from rwt_protocol.ops import OP_MODELS

SUITE = load_suite()
APPLIES = 'profiles = "strict"\ndialects = ["ros1", "ros2"]\n'


def test_every_requirement_is_covered_by_a_case() -> None:
    uncovered = [r for r in SUITE.requirements if not SUITE.cases_for(r)]
    assert uncovered == []


def test_every_case_names_existing_requirements() -> None:
    for case in SUITE.cases:
        assert case.requirements, case.id
        assert set(case.requirements) <= set(SUITE.requirements), case.id


def test_requirements_cover_every_decision_and_reference_scenario() -> None:
    ids = set(SUITE.requirements)
    assert {f"D{n}" for n in range(1, 31)} <= ids
    assert {f"ref.W{n}" for n in range(1, 14)} <= ids


def test_every_op_of_both_editions_has_its_example() -> None:
    ids = set(SUITE.requirements)
    missing = [op for op in OP_MODELS if f"example.{op}" not in ids]
    assert missing == []


def test_every_requirement_cites_a_source() -> None:
    pattern = re.compile(r"spec|^D\d+$|REF §")
    assert [r.id for r in SUITE.requirements.values() if not pattern.search(r.source)] == []


def test_pending_cases_say_why() -> None:
    for case in SUITE.cases:
        if case.pending is not None:
            assert len(case.pending) > 10, case.id


def _write_suite(folder: Path, cases: str) -> Path:
    (folder / "cases").mkdir()
    (folder / "requirements.toml").write_text(
        '[[requirement]]\nid = "r1"\nsource = "spec 1"\nstatement = "s"\n'
    )
    (folder / "cases" / "c.toml").write_text(cases)
    return folder


def test_a_case_naming_an_unknown_requirement_is_refused(tmp_path: Path) -> None:
    folder = _write_suite(
        tmp_path,
        '[[case]]\nid = "c"\nrequirements = ["r2"]\n' + APPLIES + "steps = []\n",
    )
    with pytest.raises(SuiteError, match="unknown requirements"):
        load_suite(folder)


def test_a_step_with_two_actions_is_refused(tmp_path: Path) -> None:
    folder = _write_suite(
        tmp_path,
        '[[case]]\nid = "c"\nrequirements = ["r1"]\n'
        + APPLIES
        + "steps = [{ sync = true, close = true }]\n",
    )
    with pytest.raises(SuiteError, match="one action key"):
        load_suite(folder)


def test_a_repeated_case_id_is_refused(tmp_path: Path) -> None:
    case = '[[case]]\nid = "c"\nrequirements = ["r1"]\n' + APPLIES + "steps = []\n"
    folder = _write_suite(tmp_path, case + case)
    with pytest.raises(SuiteError, match="repeats"):
        load_suite(folder)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_every_requirement_has_a_case_on_each_transport(transport: str) -> None:
    """Issue 6: both transports pass every requirement, so each needs a case that runs there."""
    covered = {r for c in SUITE.cases if transport in c.transports for r in c.requirements}
    assert set(SUITE.requirements) - covered == set()


def test_only_the_frame_size_cases_depend_on_the_transport() -> None:
    single = {c.id: set(c.transports) for c in SUITE.cases if set(c.transports) != set(TRANSPORTS)}
    assert single == {"connections.frame-limit": {"ws"}, "connections.frame-limit-tcp": {"tcp"}}


def test_the_auth_cases_authenticate_themselves() -> None:
    authenticating = [c for c in SUITE.cases if c.authenticates]
    assert {r for c in authenticating for r in c.requirements} == {"D23", "spec1.auth.required"}


def test_send_auth_takes_known_fields_only(tmp_path: Path) -> None:
    folder = _write_suite(
        tmp_path,
        '[[case]]\nid = "c"\nrequirements = ["r1"]\n' + APPLIES + "authenticates = true\n"
        'steps = [{ send_auth = { secret = "x" } }]\n',
    )
    with pytest.raises(SuiteError, match="send_auth takes a table"):
        load_suite(folder)
