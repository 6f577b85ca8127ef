"""Handlers of ``fragment`` and ``png`` (spec 3.1.1-3.1.2, D19, D20).

A completed message is processed as if it had arrived as one frame, so the
parts of any op work, including parts of a ``png`` op and a ``png`` op inside
fragments. Parts are kept per connection (``Session.fragments``) and expire on
the session's timer. A PNG's header is checked here; its inflating is paced by
the connection's budget and may run off the event loop (``Session.inflate_png``,
docs/limits.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...codecs.png import read_png
from ...errors import RemoteProtocolError
from ...framing.fragments import PartKind

if TYPE_CHECKING:
    from ...ops import Fragment, Png
    from .context import HandlerContext

__all__ = ["fragment", "png"]


def fragment(session: HandlerContext, op: Fragment, now: float) -> None:
    """Take one part of a fragmented message; process the message once complete (D19).

    Raises:
        RemoteProtocolError: a duplicate or inconsistent part, or a bound exceeded.
    """
    text = session.fragments.add(PartKind.FRAGMENT, op.id, op.num, op.total, data=op.data, now=now)
    session.watch_fragments()
    if text is not None:
        session.receive_frame(text, now)


def png(session: HandlerContext, op: Png, now: float) -> None:
    """Decode a PNG-compressed op, or one part of it, and process it (D20).

    ``id``, ``num`` and ``total`` come together (a part) or not at all (a whole
    PNG); a ``total`` of 1 with ``num`` 0 is a whole PNG too.

    Raises:
        RemoteProtocolError: a partial set of ``id``/``num``/``total``, a bad part
            (see ``fragment``), or data that is not a PNG within the size bound.
    """
    data: str | None = op.data
    if op.num is not None or op.total is not None:
        if op.id is None or op.num is None or op.total is None:
            raise RemoteProtocolError("id, num and total must be given together")
        data = session.fragments.add(PartKind.PNG, op.id, op.num, op.total, data=op.data, now=now)
        session.watch_fragments()
    if data is not None:
        png = read_png(data, max_bytes=session.config.max_message_size)
        session.inflate_png(png, op.id, now)
