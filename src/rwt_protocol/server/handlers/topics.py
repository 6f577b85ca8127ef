"""Handlers of the topic ops (spec 3.3.1-3.3.5, D3, D7, D11, D26)."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

from ...errors import GraphError
from ...levels import StatusLevel
from ...names import resolve_name
from ...qos import MAX_DEPTH
from ...shortcuts import enabled
from ..publisher_qos import PublisherQos
from ..subscriptions import BatchTopicSubscription, TopicSubscription

if TYPE_CHECKING:
    from ...ops import Advertise, PublishView, Subscribe, Unadvertise, Unsubscribe
    from ...ops.qos import Qos
    from ...ports import PublishNote
    from ...qos import QosProfile
    from .context import HandlerContext

__all__ = [
    "advertise",
    "publish",
    "report_type_warning",
    "subscribe",
    "unadvertise",
    "unsubscribe",
]

_MAX_LISTED = 8

_BATCH_SINK = enabled("rosbridge-batch-sink")
# a subscription takes a run of messages in one call (``BatchTopicSubscription``)


def advertise(session: HandlerContext, op: Advertise, now: float) -> None:
    """Register the client as a publisher of ``op.topic`` (spec 3.3.1).

    A ``qos`` (protocol 2.1.0) replaces ``latch`` and ``queue_size``, as the spec
    says; the topic's first registration with one fixes its QoS (D62).

    Raises:
        GraphError: bad or unknown type, or the topic has another type.
        LimitError: past ``--max-advertisements`` or ``max_ids_per_topic``.
    """
    _register(session, "advertise", op.topic, op.type, op.id, now, latch=op.latch, qos=op.qos)


def _register(
    session: HandlerContext,
    op_name: str,
    spelling: str,
    type_name: str,
    op_id: str | int | None,
    now: float,
    *,
    latch: bool,
    qos: Qos | None = None,
) -> None:
    """Advertise ``spelling`` as ``type_name`` for the client, under ``op_id``.

    What ``advertise`` does, and a ``publish`` with ``type`` the client has not
    advertised (D48): the caps, the graph's checks, the id kept for ``unadvertise``.
    With ``qos``, ``latch`` is not read (spec 4.3.1 of 2.1.0), the client is
    warned when the topic keeps another registration's QoS (D62), and of what
    concerns its offer from ``now`` on (``publisher_qos``: a subscription it
    cannot meet, D64; a missed deadline, D65).

    Raises:
        GraphError: bad or unknown type, or the topic has another type.
        LimitError: past ``--max-advertisements`` or ``max_ids_per_topic``.
    """
    topic = resolve_name(spelling)
    holdings = session.holdings
    ids = holdings.advertisements.get(topic)
    if ids is None:
        session.check_cap(holdings.offered(), session.config.max_advertisements, "advertisements")
    elif op_id not in ids:
        session.check_cap(len(ids), session.config.max_ids_per_topic, f"ids on {spelling}")
    profile = None if qos is None or not session.config.compat.reads_qos else qos.profile()
    watch = None
    if profile is not None:
        warn = functools.partial(_warn_publisher, session, op_name, op_id)
        watch = PublisherQos(spelling, profile, session.call_at, warn, now)
    canonical = session.graph.advertise(
        session.client_id,
        spelling,
        type_name,
        latch=latch and profile is None,
        qos=profile,
        watch=watch,
    )
    holdings.add_advertisement(topic, op_id)
    report_type_warning(session, op_name, canonical, op_id)
    if profile is not None:
        _report_offer(session, op_name, spelling, profile, op_id)
    session.report(StatusLevel.INFO, f"{op_name}: {spelling} advertised as {canonical}", op_id)


def _warn_publisher(
    session: HandlerContext, op_name: str, op_id: str | int | None, text: str
) -> None:
    """A warning to the client of its offer (``PublisherQos``), with its registration's id."""
    session.report(StatusLevel.WARNING, f"{op_name}: {text}", op_id)


def _report_offer(
    session: HandlerContext,
    op_name: str,
    spelling: str,
    profile: QosProfile,
    op_id: str | int | None,
) -> None:
    """Warn of a capped depth, and of a topic that keeps another registration's QoS (D62)."""
    _report_capped(session, op_name, profile, op_id)
    offered = session.graph.offered_qos(spelling)
    if offered is not None and offered != profile.for_publisher():
        session.report(
            StatusLevel.WARNING,
            f"{op_name}: {spelling} keeps the QoS of its first registration"
            f" ({offered.describe()}); this one's ({profile.describe()}) is not used",
            op_id,
        )


def _report_capped(
    session: HandlerContext, op_name: str, profile: QosProfile, op_id: str | int | None
) -> None:
    """Warn when a ``qos.depth`` (or ``keep_all``) is more than the server keeps (D63)."""
    if profile.capped:
        session.report(
            StatusLevel.WARNING,
            f"{op_name}: qos.depth {profile.depth} capped at {MAX_DEPTH}",
            op_id,
        )


def report_type_warning(
    session: HandlerContext, op: str, type_name: str, op_id: str | int | None
) -> None:
    """A warning status when a link of the graph cannot carry ``type_name`` (docs/ros2.md)."""
    warning = session.graph.type_warning(type_name)
    if warning:
        session.report(StatusLevel.WARNING, f"{op}: {warning}", op_id)


def unadvertise(session: HandlerContext, op: Unadvertise, now: float) -> None:
    """Drop one advertise id, or all of them, for ``op.topic`` (spec 3.3.2).

    Raises:
        GraphError: warning level when the client does not advertise the topic
            or has no advertisement with ``op.id`` (spec 3.3.2, D3).
    """
    topic = resolve_name(op.topic)
    ids = session.holdings.advertisements.get(topic)
    if ids is None:
        raise GraphError(f"{op.topic} is not advertised by this client", level=StatusLevel.WARNING)
    if op.id is not None and op.id not in ids:
        raise GraphError(
            f"no advertisement with id {op.id!r} on {op.topic}", level=StatusLevel.WARNING
        )
    if session.holdings.drop_advertisement(topic, op.id):
        session.graph.unadvertise(session.client_id, topic)
    session.report(StatusLevel.INFO, f"unadvertise: {op.topic} unadvertised", op.id)


def publish(session: HandlerContext, op: PublishView, now: float) -> None:
    """Publish ``op.msg`` on ``op.topic`` (spec 3.3.3).

    A ``publish`` with ``type`` from a client that does not advertise the topic
    advertises it first, as ``advertise`` with the op's ``id`` and ``latch`` would
    (D48; protocol 2.0.0, docs/reference-behaviour.md §13.3), unless the server
    runs ``--compat rosbridge-2.1``. Once the client advertises the topic, ``type``
    is not read again. A warning lists the fields filled with defaults (spec 3.3.3, D7),
    and one tells of the safety envelope's clamp or drop, once per episode (D67).

    Raises:
        GraphError: unknown topic type, a ``type`` other than the topic's, or a
            message that does not fit it (D9), or the safety envelope refused it
            (D67); nothing is published.
        LimitError: the advertisement is past ``--max-advertisements``.
    """
    if op.type is not None and _advertises(session, op.topic):
        _register(session, "publish", op.topic, op.type, op.id, now, latch=op.latch, qos=op.qos)

    def noted(note: PublishNote) -> None:
        if note.first:  # a stream of commands: one warning per episode
            session.report(StatusLevel.WARNING, f"publish: {note.text}", op.id)

    missing = session.graph.publish(
        session.client_id, op.topic, op.msg, latch=op.latch, path="$.msg", notes=noted
    )
    if missing:
        listed = ", ".join(missing[:_MAX_LISTED])
        more = f" and {len(missing) - _MAX_LISTED} more" if len(missing) > _MAX_LISTED else ""
        session.report(StatusLevel.WARNING, f"publish: filled with defaults: {listed}{more}", op.id)


def _advertises(session: HandlerContext, spelling: str) -> bool:
    """Whether a ``publish`` with ``type`` on ``spelling`` advertises it first (D48)."""
    if not session.config.compat.publish_advertises:
        return False
    return resolve_name(spelling) not in session.holdings.advertisements


def subscribe(session: HandlerContext, op: Subscribe, now: float) -> None:
    """Add a subscription to ``op.topic`` (spec 3.3.4, merging per D11).

    One made on the transport's lossy channel gets its messages there while all
    its ids came there (D36, ``TopicSubscription.lossy``). Its ``qos`` (protocol
    2.1.0), merged with its other ids', is what it asks of the topic (D63-D65).

    Raises:
        GraphError: the type is unknown, cannot be inferred, or conflicts.
    """
    topic = resolve_name(op.topic)
    subscriptions = session.holdings.subscriptions
    subscription = subscriptions.get(topic)
    if subscription is None:
        cap = session.config.max_subscriptions
        session.check_cap(len(subscriptions), cap, "subscriptions")
    elif op.id not in subscription.requests:
        cap = session.config.max_ids_per_topic
        session.check_cap(len(subscription.requests), cap, f"ids on {op.topic}")
    if subscription is None:
        subscription = _new_subscription(session, topic, op.topic)
        subscription.add(op, now, lossy=session.input_lossy)
        subscription.type_name = session.graph.subscribe(
            session.client_id, op.topic, op.type, subscription, qos=subscription.requested_qos
        )
        session.holdings.add_subscription(topic, subscription)
        report_type_warning(session, "subscribe", subscription.type_name, op.id)
    else:
        asked = subscription.requested_qos
        subscription.add(op, now, lossy=session.input_lossy)
        if op.type is not None or subscription.requested_qos != asked:
            session.graph.subscribe(
                session.client_id,
                op.topic,
                op.type,
                subscription,
                qos=subscription.requested_qos,
            )
    if op.qos is not None and session.config.compat.reads_qos:
        _report_capped(session, "subscribe", op.qos.profile(), op.id)
    cap = session.config.max_queue_length
    if op.queue_length > cap:
        session.report(
            StatusLevel.WARNING, f"subscribe: queue_length {op.queue_length} capped at {cap}", op.id
        )
    session.report(StatusLevel.INFO, f"subscribe: subscribed to {op.topic}", op.id)


def unsubscribe(session: HandlerContext, op: Unsubscribe, now: float) -> None:
    """Remove the subscription ``op.id``, or all of them, on ``op.topic`` (spec 3.3.5).

    Raises:
        GraphError: warning level when not subscribed or the id is unknown (D11).
    """
    topic = resolve_name(op.topic)
    subscription = session.holdings.subscriptions.get(topic)
    if subscription is None:
        raise GraphError(f"not subscribed to {op.topic}", level=StatusLevel.WARNING)
    if op.id is None:
        subscription.close()
    elif not subscription.remove(op.id, now):
        raise GraphError(
            f"no subscription with id {op.id!r} on {op.topic}", level=StatusLevel.WARNING
        )
    if not subscription.requests:
        subscription.close()
        session.holdings.drop_subscription(topic)
        session.graph.unsubscribe(session.client_id, topic)
    session.report(StatusLevel.INFO, f"unsubscribe: unsubscribed from {op.topic}", op.id)


def _new_subscription(session: HandlerContext, topic: str, spelling: str) -> TopicSubscription:
    """A subscription of ``session`` to ``topic``: one that takes runs unless switched off."""
    config = session.config
    max_queue = config.max_queue_length
    warn = functools.partial(session.report, StatusLevel.WARNING)
    qos_warn, lifespan = session.warn_subscription, config.qos_lifespan_s
    reads_qos = config.compat.reads_qos
    if _BATCH_SINK:
        return BatchTopicSubscription(
            topic,
            spelling,
            session.deliver,
            session.deliver_many,
            session.call_at,
            max_queue=max_queue,
            warn=warn,
            qos_warn=qos_warn,
            default_lifespan_s=lifespan,
            reads_qos=reads_qos,
            deliver_ruled=session.deliver_ruled,
        )
    return TopicSubscription(
        topic,
        spelling,
        session.deliver,
        session.call_at,
        max_queue=max_queue,
        warn=warn,
        qos_warn=qos_warn,
        default_lifespan_s=lifespan,
        reads_qos=reads_qos,
        deliver_ruled=session.deliver_ruled,
    )
