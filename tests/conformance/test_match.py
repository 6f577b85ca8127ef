"""Pattern matching and substitution of the conformance cases."""

from __future__ import annotations

import math

import pytest

from rwt_conformance.match import match, substitute


def test_object_patterns_match_a_subset_of_keys() -> None:
    assert match({"op": "publish"}, {"op": "publish", "topic": "/t"}, {}) is None
    assert (
        match({"op": "publish"}, {"op": "status"}, {}) == "$.op: expected 'publish', got 'status'"
    )
    assert match({"id": 1}, {"op": "x"}, {}) == "$.id: missing"


def test_arrays_match_element_by_element() -> None:
    assert match([1, 2], [1, 2], {}) is None
    assert match([1, 2], [1, 2, 3], {}) == "$: expected 2 items, got 3"
    assert match({"a": [{"b": 1}]}, {"a": [{"b": 2}]}, {}) == "$.a[0].b: expected 1, got 2"


@pytest.mark.parametrize(
    ("pattern", "good", "bad"),
    [
        ("<str>", "x", 1),
        ("<int>", 3, True),
        ("<number>", 2.5, "2.5"),
        ("<bool>", False, 0),
        ("<object>", {}, []),
        ("<array>", [], {}),
        ("<positive>", 1, 0),
        ("<null>", None, 0),
        ("<re:^subscribe: >", "subscribe: bad", "publish: bad"),
    ],
)
def test_sentinels(pattern: str, good: object, bad: object) -> None:
    assert match({"v": pattern}, {"v": good}, {}) is None
    assert match({"v": pattern}, {"v": bad}, {}) is not None


def test_absent_and_any() -> None:
    assert match({"id": "<absent>"}, {"op": "x"}, {}) is None
    assert match({"id": "<absent>"}, {"id": 1}, {}) is not None
    assert match({"id": "<any>"}, {"id": None}, {}) is None
    assert match({"id": "<any>"}, {}, {}) is not None


def test_bool_is_not_a_number_and_numbers_compare_by_value() -> None:
    assert match(1, True, {}) is not None
    assert match(1, 1.0, {}) is None
    assert match(math.nan, math.nan, {}) is None


def test_captures_are_kept_only_when_the_whole_pattern_matches() -> None:
    captures: dict[str, object] = {}
    assert match({"id": "<capture:rid>", "op": "x"}, {"id": "r1", "op": "y"}, captures) is not None
    assert captures == {}
    assert match({"id": "<capture:rid>"}, {"id": "r1"}, captures) is None
    assert captures == {"rid": "r1"}


def test_substitute_keeps_types_and_splices_text() -> None:
    variables = {"ns": "rwtc_1/c2", "i": 7}
    frame = {"topic": "/${ns}/t", "msg": {"data": "${i}", "label": "n${i}"}, "x": "<null>"}
    assert substitute(frame, variables) == {
        "topic": "/rwtc_1/c2/t",
        "msg": {"data": 7, "label": "n7"},
        "x": None,
    }
    with pytest.raises(KeyError):
        substitute("${missing}", variables)


def test_byte_strings() -> None:
    assert match("<bytes>", b"", {}) is None
    assert match("<bytes>", "", {}) == "$: expected bytes, got ''"
    assert match({"d": "<bytes:0102FF>"}, {"d": b"\x01\x02\xff"}, {}) is None
    assert (
        match("<bytes:0102ff>", b"\x01\x02", {})
        == "$: expected the bytes 0102ff, got <2 bytes: 0102>"
    )
    assert match("<bytes:00>", [0], {}) == "$: expected the bytes 00, got [0]"
