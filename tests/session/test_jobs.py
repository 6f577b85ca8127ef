"""Work a session leaves to its transport, as the connection runtime runs it.

A transport that called ``run_jobs`` gets a ``png`` op's inflating as an input
job (the reader waits for it: ops keep their order) and a ``png`` subscription's
deflating as a background job (pngout); each outcome comes back through
``finish_job``. Whatever the outcome (the text, a refusal, a bug in the job),
the peer hears of it and the session goes on (docs/limits.md).
"""

from __future__ import annotations

import json

import pytest

from rwt_graph.graph import Graph
from rwt_protocol.codecs.png import encode_png
from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.server.encoding import EncodeFailure
from tests.conftest import Peer


def _running(graph: Graph, name: str) -> Peer:
    peer = Peer(graph, name)
    peer.session.jobs.transport_runs = True  # as the pump does
    return peer


def _publish_png(text: str) -> str:
    op = {"op": "publish", "topic": "/c", "msg": {"data": text}}
    return json.dumps({"op": "png", "data": encode_png(json.dumps(op).encode())})


@pytest.fixture
def listener(graph: Graph) -> Peer:
    peer = Peer(graph, "listener")
    peer.send(op="subscribe", topic="/c", type="std_msgs/String")
    return peer


def test_an_inflated_png_op_is_handled_in_its_turn(graph: Graph, listener: Peer) -> None:
    sender = _running(graph, "sender")
    sender.send(op="advertise", topic="/c", type="std_msgs/String")
    sender.send_raw(_publish_png("inflated"))
    assert sender.session.jobs.waiting and listener.received() == []  # not on the loop
    job = sender.session.jobs.take()
    assert job is not None
    sender.session.finish_job(job, job.run(), 0.0)
    assert [m["msg"] for m in listener.received()] == [{"data": "inflated"}]


def test_a_refused_or_broken_inflating_is_told_and_the_session_goes_on(
    graph: Graph, listener: Peer
) -> None:
    sender = _running(graph, "sender")
    sender.send(op="advertise", topic="/c", type="std_msgs/String")
    for outcome in (RemoteProtocolError("data is not a valid PNG image"), ZeroDivisionError()):
        sender.send_raw(_publish_png("x"))
        job = sender.session.jobs.take()
        assert job is not None
        sender.session.finish_job(job, outcome, 0.0)
    assert [s["msg"] for s in sender.statuses()] == [
        "png: data is not a valid PNG image",
        "png: internal error",
    ]
    sender.send_raw(_publish_png("after"))
    job = sender.session.jobs.take()
    assert job is not None
    sender.session.finish_job(job, job.run(), 0.0)
    assert [m["msg"] for m in listener.received()] == [{"data": "after"}]


def test_a_deflating_that_fails_is_told_to_its_subscriber(graph: Graph, pub: Peer) -> None:
    sub = _running(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", compression="png")
    outcomes = [EncodeFailure("publish", "too deep"), ZeroDivisionError()]
    for outcome in outcomes:
        pub.send(op="publish", topic="/c", msg={"data": "x"})
        job = sub.session.jobs.take_background()
        assert job is not None
        sub.session.finish_job(job, outcome, 0.0)
    assert [s["msg"] for s in sub.statuses()] == [
        "subscribe: cannot send a message of /c as png",
        "subscribe: internal error",
    ]
    assert sub.session.drop_background_job(job) is False  # taken already: nothing to withdraw


@pytest.fixture
def pub(graph: Graph) -> Peer:
    peer = Peer(graph, "pub")
    peer.send(op="advertise", topic="/c", type="std_msgs/String")
    return peer
