"""Large samples: each buffer made where the next one can reuse its memory.

Both ways, a burst of large samples (camera images) faster than the other end
builds a queue, and a queue of fresh 1 MB buffers is paid in page faults: every
buffer past the heap kept (``rwt_transports.process.allocator``) is memory the kernel
maps and zeroes anew. The link therefore queues what exists already and makes
each copy just before it is used, freed right after (the Z3 link benchmark,
benchmarks/README.md, "Scaling out", measured with 1 MB images).

Outward (``DeferredEncoder``, the ``zenoh-deferred-encode`` shortcut): the
link's tap runs on the event loop and hands each local sample to the outbox
(``outbox``), whose thread puts it with congestion control BLOCK. Serialized on
the loop, a burst of images queued one fresh CDR buffer per image there:
process A took about 120 page faults and 400-700 us of its event loop per image,
where serializing one with the heap warm takes 43 us. A message whose
top-level ``uint8[]`` fields hold ``DEFER_BYTES`` or more is therefore queued as
it is (the graph's messages are never mutated after publication,
``MessageEvent``) and serialized by the outbox's thread right before its put.
The bytes are the general path's (``payload.encode_message``): the same rosbags
serializer, given the same rosbags object. Their length is computed on the
loop, so the outbox's byte bound counts a deferred sample exactly.

Inward (``held_payload``, ``payload_bytes``, the ``zenoh-late-copy``
shortcut): a remote sample of ``DEFER_BYTES`` or more waits in the link's inbox
as Zenoh's own ``ZBytes`` (buffers Zenoh made anyway), and its ``bytes`` are
made on the event loop right before it is decoded. Copied on Zenoh's callback
thread, the inbox was a queue of fresh ``bytes``: 76 page faults per image in
process B, about 1 after the change. The inbox bounds it by its length as
before (docs/limits.md, "Zenoh peers"); a sample that large is always
fragmented by Zenoh (a batch holds at most 64 KiB), so the buffers it holds are
its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rwt_graph.types.spec import ArrayKind, is_bytes_base
from rwt_protocol.shortcuts import enabled

from .payload import owned_cdr

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.types import MessageType, TypeRegistry

__all__ = [
    "DEFER_BYTES",
    "Deferred",
    "DeferredEncoder",
    "byte_fields",
    "held_payload",
    "payload_bytes",
]

DEFER_BYTES = 64 * 1024
"""Bytes of top-level ``uint8[]`` values from which a message is serialized late."""

#: The ``zenoh-deferred-encode`` shortcut (shortcuts.py); off, the loop serializes all.
_ON = enabled("zenoh-deferred-encode")
#: The ``zenoh-late-copy`` shortcut (shortcuts.py); off, payloads are copied on arrival.
_LATE_COPY = enabled("zenoh-late-copy")


def held_payload(payload: Any, *, late: bool = _LATE_COPY) -> Any:
    """What the inbox holds of a sample's ``payload`` (a ``zenoh.ZBytes``), on Zenoh's thread.

    Returns:
        ``payload`` itself from ``DEFER_BYTES`` on (when ``late``), else its ``bytes``.
    """
    return payload if late and len(payload) >= DEFER_BYTES else payload.to_bytes()


def payload_bytes(held: Any) -> bytes:
    """The ``bytes`` of what ``held_payload`` returned (on the event loop)."""
    return held if type(held) is bytes else held.to_bytes()


class Deferred:
    """A sample's CDR payload, made when ``make`` is called (on the outbox's thread).

    ``len()`` is the exact length of what ``make`` returns, bytes.
    """

    __slots__ = ("_make", "nbytes")

    def __init__(self, nbytes: int, make: Callable[[], bytes | bytearray]) -> None:
        self.nbytes = nbytes
        self._make = make

    def __len__(self) -> int:
        return self.nbytes

    def make(self) -> bytes | bytearray:
        """The CDR bytes with their encapsulation header, as ``encode_message`` makes them."""
        return self._make()


def byte_fields(mtype: MessageType) -> tuple[str, ...]:
    """The names of ``mtype``'s top-level ``uint8[]``/``char[]`` fields (held as ``bytes``)."""
    return tuple(
        spec.name
        for spec in mtype.fields
        if spec.type.array is not ArrayKind.NONE
        and not spec.type.is_message
        and is_bytes_base(spec.type.base)
    )


class DeferredEncoder:
    """Decides, per message, whether the outbox's thread serializes it (see the module text).

    Args:
        registry: the graph's type registry (ROS 2: the link refuses others).
        on: whether to defer at all; the ``zenoh-deferred-encode`` shortcut by default.
    """

    def __init__(self, registry: TypeRegistry, *, on: bool = _ON) -> None:
        self._registry = registry
        self._on = on
        self._fields: dict[str, tuple[MessageType, tuple[str, ...]]] = {}

    def defer(self, mtype: MessageType, msg: dict[str, object]) -> Deferred | None:
        """``msg`` as a ``Deferred`` payload, or None when the loop should serialize it now.

        None unless its top-level ``uint8[]`` values hold ``DEFER_BYTES`` or more
        together (a message without such a field costs one dict lookup).

        Raises:
            KeyError: the typestore lacks the type (as the general path does).
        """
        if not self._on:
            return None
        known = self._fields.get(mtype.name)
        if known is None or known[0] is not mtype:
            known = self._fields[mtype.name] = (mtype, byte_fields(mtype))
        fields = known[1]
        if not fields:
            return None
        large = 0
        for name in fields:
            value = msg.get(name)
            if type(value) is bytes:
                large += len(value)
        if large < DEFER_BYTES:
            return None
        store = self._registry.typestore()
        obj = mtype.to_rosbags_converter(store)(msg)  # views of the message's bytes, no copy
        name = mtype.rosbags_name
        size = 4 + store.get_msgdef(name).getsize_cdr(0, obj, store)
        return Deferred(size, lambda: owned_cdr(store.serialize_cdr(obj, name)))
