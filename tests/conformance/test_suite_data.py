"""The suite's data: every requirement has a case, every case names requirements."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from rwt_conformance.model import (
    TRANSPORTS,
    Dialect,
    Profile,
    Step,
    StepKind,
    SuiteError,
    load_suite,
)
from rwt_protocol.ops import OP_MODELS
from tests.support.shipped_suite import SUITE

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
    """Both transports pass every requirement, so each needs a case that runs there."""
    covered = {r for c in SUITE.cases if transport in c.transports for r in c.requirements}
    assert set(SUITE.requirements) - covered == set()


def test_only_the_frame_size_cases_depend_on_the_transport() -> None:
    single = {c.id: set(c.transports) for c in SUITE.cases if set(c.transports) != set(TRANSPORTS)}
    assert single == {
        "connections.frame-limit": {"ws"},
        "connections.frame-limit-tcp": {"tcp", "webrtc"},  # a data channel reads it as TCP
    }


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


def test_every_case_says_where_it_applies_and_why_not_elsewhere() -> None:
    """What a case leaves out (a profile, a dialect) has a reason citing the docs."""
    cites = re.compile(r"REF §\d|\bD\d+\b")
    for case in SUITE.cases:
        assert case.profiles, case.id
        assert case.dialects, case.id
        for profile in Profile:
            for dialect in Dialect:
                reason = case.skip_reason(profile, dialect)
                if reason is not None:
                    assert cites.search(reason), (case.id, profile, dialect, reason)


def _reference_steps() -> list[tuple[str, Dialect, Step]]:
    """Every step that runs in the reference profile, with its case and dialect."""
    return [
        (case.id, dialect, step)
        for case in SUITE.cases
        for dialect in Dialect
        if case.skip_reason(Profile.REFERENCE, dialect) is None
        for step in case.steps
        if step.runs_in(Profile.REFERENCE, dialect)
    ]


def _stalls_the_reference(step: Step) -> bool:
    """A frame REF §1.4 says kills the reference's worker for that client."""
    if step.kind is StepKind.SEND_RAW:
        try:
            value = json.loads(str(step.value))
        except ValueError:
            return False  # invalid JSON is buffered, not fatal (REF §1.3)
        if isinstance(value, (str, list)):
            return "id" in value or "op" in value
        return not isinstance(value, dict)
    if step.kind is not StepKind.SEND or not isinstance(step.value, dict):
        return False
    frame = step.value
    size = frame.get("fragment_size")
    return (
        isinstance(frame.get("op"), (list, dict))
        or ("png" in frame and "msg" not in frame)
        or ("fragment_size" in frame and (not isinstance(size, int) or size < 1))
    )


def test_the_reference_profile_uses_no_connection_after_stalling_it() -> None:
    """A stalled connection is never served again; other connections are (REF §1.4)."""
    stalled: set[tuple[str, Dialect, str]] = set()
    used_after: list[tuple[str, Dialect, str]] = []
    for case_id, dialect, step in _reference_steps():
        key = (case_id, dialect, step.on)
        if key in stalled and step.kind is not StepKind.CLOSE:
            used_after.append(key)
        if _stalls_the_reference(step):
            stalled.add(key)
    assert stalled  # the suite does check that other connections keep being served
    assert used_after == []


def test_the_reference_profile_sends_no_cbor() -> None:
    """REF §3.2: rosbridge_suite accepts no CBOR from clients."""
    assert [(c, d) for c, d, s in _reference_steps() if s.kind is StepKind.SEND_BINARY] == []


def test_the_reference_profile_sends_fragments_in_order_and_takes_float_totals() -> None:
    """REF §3.4: parts are joined in arrival order; outgoing ``total`` is a float."""
    sent: dict[tuple[str, Dialect, str], list[tuple[object, object]]] = {}
    for case_id, dialect, step in _reference_steps():
        frame = step.value if isinstance(step.value, dict) else {}
        if frame.get("op") != "fragment":
            continue
        if step.kind is StepKind.SEND:
            key = (case_id, dialect, str(frame.get("id")))
            sent.setdefault(key, []).append((frame.get("num"), frame.get("total")))
        else:
            assert frame.get("total") != "<int>", case_id
    # a message meant to be reassembled: every num of 0..total-1 once, one integer total
    whole = {
        key: [num for num, _ in parts]
        for key, parts in sent.items()
        if {total for _, total in parts} == {len(parts)}
        and sorted(num for num, _ in parts) == list(range(len(parts)))  # type: ignore[type-var]
    }
    assert whole
    assert all(nums == sorted(nums) for nums in whole.values()), whole  # type: ignore[type-var]
    # anything else must be refused outright: a kept part stays in a store shared by all
    # clients, and its expiry later loses another message's part
    kept = [
        key
        for key, parts in sent.items()
        if key not in whole and any(num is not None and total is not None for num, total in parts)
    ]
    assert kept == []


def test_the_ros1_reference_profile_uses_no_ros2_only_feature() -> None:
    """0.11.x has no action ops (REF §1.3) and no call timeout (REF §2.6)."""
    action_ops = {op for op in OP_MODELS if "action" in op}
    used = [
        c
        for c, d, s in _reference_steps()
        if d is Dialect.ROS1
        and s.kind is StepKind.SEND
        and isinstance(s.value, dict)
        and (str(s.value.get("op")) in action_ops or "timeout" in s.value)
    ]
    assert used == []


def test_each_recorded_defect_of_the_ros2_reference_cites_its_section() -> None:
    """Steps expecting what rosbridge_suite 2.1.0 does against the spec cite REF §12 and
    apply to the ROS 2 reference only; the case's title says so too."""
    recorded = [case for case in SUITE.cases if case.defects(Profile.REFERENCE, Dialect.ROS2)]
    assert len(recorded) == 10
    for case in recorded:
        assert re.search(r"REF §[\d., §]*12\.\d", case.title), case.id
        for step in case.steps:
            if step.defect is not None:
                assert re.fullmatch(r"REF §12\.\d+", step.defect), case.id
                assert (step.profile, step.dialect) == (Profile.REFERENCE, Dialect.ROS2), case.id
                assert not step.unless_defect, case.id
    for case in SUITE.cases:
        for profile in Profile:
            assert not case.defects(profile, Dialect.ROS1), case.id  # ROS 1: unchanged
        if any(step.unless_defect for step in case.steps):
            assert case in recorded, case.id


def test_paced_sends_are_repeated_and_for_ros2_only() -> None:
    """Pacing (``pace_s``) is for 2.1.0's 10-deep subscriptions (REF §12.8); ROS 1 bursts."""
    paced = [(case.id, step) for case in SUITE.cases for step in case.steps if step.pace_s]
    assert paced
    for case_id, step in paced:
        assert step.repeat > 1, case_id
        assert step.dialect is Dialect.ROS2, case_id
        assert 0 < step.pace_s <= 0.02, case_id
