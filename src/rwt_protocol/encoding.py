"""Outgoing encodings of topic messages.

A message published to N subscribers is serialized once per distinct encoding
(issue 4 "encode once"): ``MessageEvent.encoded`` caches each form, keyed by the
encoding and, for the envelope, the topic spelling the subscriber used (D26).
"""

from __future__ import annotations

from .codec import encode_json
from .outbox import OutFrame
from .ports import MessageEvent
from .subscriptions import TopicSubscription

__all__ = ["publish_frame"]


def publish_frame(subscription: TopicSubscription, event: MessageEvent) -> OutFrame:
    """Build the frame that delivers ``event`` to ``subscription``'s client.

    Returns:
        ``{"op":"publish","topic":<spelling>,"msg":<msg>}`` as JSON text; the
        ``msg`` part is encoded once per event whatever the spelling.
    """
    spelling = subscription.spelling
    msg_json = event.encoded("json:msg", lambda: encode_json(event.msg))
    data = event.encoded(
        ("json", spelling),
        lambda: b'{"op":"publish","topic":' + encode_json(spelling) + b',"msg":' + msg_json + b"}",
    )
    return OutFrame(data, droppable=True)
