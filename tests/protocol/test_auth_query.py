"""A URL token (docs/foxglove.md, Authentication): the ``auth`` op's fields in a query string.

A Foxglove client cannot send an ``auth`` op, so it carries the same fields in its
URL; the server reads them back into the op and checks it as it checks the op.
"""

from __future__ import annotations

from urllib.parse import quote

import pytest

from rwt_protocol.auth import RosauthVerifier, auth_from_query, auth_query, rosauth_op
from rwt_protocol.errors import RemoteProtocolError

SECRET = "s3cret"
T = 1_700_000_000.0


def _op(**changes: object) -> str:
    fields: dict[str, object] = {
        "client": "10.0.0.5",
        "dest": "robot.local",
        "rand": "a b&c=d",  # characters the query string must escape
        "t": T,
        "level": "admin",
        "end": T + 60,
    }
    fields.update(changes)
    return auth_query(rosauth_op(SECRET, **fields))  # type: ignore[arg-type]


def test_a_token_reads_back_as_the_op_it_came_from_and_passes_the_check() -> None:
    op = auth_from_query(_op())
    assert op is not None
    fields = (op.client, op.dest, op.rand, op.level)
    assert fields == ("10.0.0.5", "robot.local", "a b&c=d", "admin")
    assert (op.t, op.end) == (T, T + 60)
    assert RosauthVerifier(SECRET).problem(op, T + 1) is None
    assert RosauthVerifier("other").problem(op, T + 1) == "MAC does not match"
    assert RosauthVerifier(SECRET).problem(op, T + 61) is not None  # expired


def test_other_parameters_are_ignored_and_no_mac_is_no_token() -> None:
    assert auth_from_query("") is None
    assert auth_from_query("foo=1&bar=") is None
    op = auth_from_query("ds=foxglove-websocket&" + _op() + "&x=1")
    assert op is not None and op.level == "admin"


@pytest.mark.parametrize(
    ("query", "says"),
    [
        (_op() + "&mac=00", "mac is given twice"),
        ("mac=ab&client=c", "dest, rand, t, level, end missing"),
        (_op().replace(f"t={T:.0f}", "t=soon"), "t is not a number"),
        (_op().replace(f"end={T + 60:.0f}", "end=inf"), "end is not a number"),
        ("&".join(f"p{n}=1" for n in range(40)), "unreadable auth query"),
    ],
    ids=["twice", "missing", "t-not-a-number", "end-infinite", "too-many-fields"],
)
def test_an_unreadable_token_is_refused_with_what_is_wrong(query: str, says: str) -> None:
    with pytest.raises(RemoteProtocolError, match=says):
        auth_from_query(query)


def test_the_query_escapes_every_field() -> None:
    query = _op(level="a&b")
    assert "level=" + quote("a&b", safe="") in query
    op = auth_from_query(query)
    assert op is not None and op.level == "a&b"
