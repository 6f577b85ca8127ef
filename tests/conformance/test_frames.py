"""How the runner reads CBOR frames and makes auth ops (D21, D23, REF §3.2)."""

from __future__ import annotations

import struct
import time

import cbor2
import pytest

from rwt_conformance.frames import AUTH_VALIDITY_S, NESTING_PROBLEM, auth_op, decode_frame
from rwt_protocol.auth import RosauthVerifier
from rwt_protocol.ops import Auth


@pytest.mark.parametrize(
    ("tag", "packed", "values"),
    [
        (69, struct.pack("<2H", 1, 65535), [1, 65535]),
        (72, struct.pack("2b", -1, 5), [-1, 5]),
        (79, struct.pack("<q", -(2**62)), [-(2**62)]),
        (85, struct.pack("<2f", 1.5, -2.25), [1.5, -2.25]),
        (86, struct.pack("<d", 0.1), [0.1]),
        (66, struct.pack(">I", 7), [7]),  # big-endian uint32
        (64, b"\x01\xff", [1, 255]),
    ],
)
def test_typed_arrays_show_their_tag_and_numbers(
    tag: int, packed: bytes, values: list[float]
) -> None:
    received = decode_frame(cbor2.dumps({"data": cbor2.CBORTag(tag, packed)}))
    assert received.binary
    assert received.value == {"data": {"cbor_tag": tag, "values": values}}


def test_other_tags_bytes_and_garbage() -> None:
    assert decode_frame(cbor2.dumps([cbor2.CBORTag(40000, "x"), b"\x00"])).value == [
        {"cbor_tag": 40000, "value": "x"},
        b"\x00",
    ]
    odd = decode_frame(cbor2.dumps(cbor2.CBORTag(86, b"\x00" * 3))).value  # not whole float64s
    assert odd == {"cbor_tag": 86, "value": b"\x00" * 3}
    assert decode_frame(b"\xff\x00").value == b"\xff\x00"
    assert decode_frame("{nope").value == {"<not JSON>": "{nope"}
    assert decode_frame('{"op": "x"}').binary is False


def test_hostile_json_from_a_server_is_shown_not_raised() -> None:
    deep = "[" * 100_000 + "]" * 100_000  # past the interpreter's recursion limit
    assert decode_frame(deep).problem == NESTING_PROBLEM  # the case fails with this reason
    assert decode_frame('{"s": "\\ud800"}').problem is None  # read, and shown escaped
    assert decode_frame("[NaN]").value != [0.0]  # Python servers' NaN is still read


def test_auth_ops_carry_rosauth_macs() -> None:
    verifier = RosauthVerifier("k")
    now = time.time()
    valid = auth_op("k", {}, "robot")
    assert valid["dest"] == "robot"
    assert valid["end"] == valid["t"] + AUTH_VALIDITY_S  # type: ignore[operator]
    assert verifier.problem(Auth.model_validate(valid), now) is None
    expired = auth_op("k", {"t_offset_s": -120, "end_offset_s": -60}, "robot")
    assert "expired" in (verifier.problem(Auth.model_validate(expired), now) or "")
    forged = auth_op("k", {"mac": "0" * 128, "level": "user"}, "robot")
    assert forged["level"] == "user"
    assert verifier.problem(Auth.model_validate(forged), now) == "MAC does not match"
    with pytest.raises(ValueError, match="seconds"):
        auth_op("k", {"t_offset_s": "soon"}, "robot")
