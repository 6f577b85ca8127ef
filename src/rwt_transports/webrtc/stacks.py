"""Which WebRTC stack answers an offer (``--webrtc-stack``; docs/webrtc.md, "Which stack").

Three stacks serve the same session (peers.py): aiortc (SCTP and DTLS in
Python), ``native`` (libdatachannel: usrsctp, libjuice; native.py, D51) and
``reactor`` (libwebrtc's dcsctp, tuned; reactor.py, D70). ``auto`` (the
default) takes, for offers of data channels only, the first of ``AUTO_ORDER`` that
imports here and reaches every ``--ice-server`` (D72: the order of the browser table,
docs/benchmarks.md). Offers asking for video tracks (``?video=``) go to libdatachannel
where it imports and is not ruled out (``--webrtc-stack aiortc``), else aiortc; other
offers with audio or video sections to aiortc.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .native import STACKS, native_ice_refusal, native_missing
from .reactor import reactor_missing

if TYPE_CHECKING:
    from collections.abc import Sequence

    from .ice import IceServer

__all__ = ["AUTO_ORDER", "STACKS", "data_stack", "stack_refusal", "video_native"]

AUTO_ORDER = ("reactor", "native", "aiortc")
"""``auto``'s preference for data channels, best first (D72): the stacks' rows of the
browser table (docs/benchmarks.md, "Over a WAN link, in Chromium")."""


def stack_refusal(stack: str, servers: Sequence[IceServer] = ()) -> str | None:
    """Why ``stack`` cannot serve here with ``servers`` (None: it can; ``auto`` always can).

    ``native`` needs libdatachannel-py (Python 3.12+) and TURN over UDP only;
    ``reactor`` needs reactor-webrtc (Linux, glibc 2.34+).
    """
    if stack not in STACKS:
        return f"{stack!r} is not one of {', '.join(STACKS)}"
    if stack == "native":
        return native_missing() or native_ice_refusal(servers)
    if stack == "reactor":
        return reactor_missing()
    return None


def data_stack(choice: str, servers: Sequence[IceServer] = ()) -> str:
    """The stack that answers an offer of data channels only, for ``--webrtc-stack choice``."""
    if choice != "auto":
        return choice
    return next(s for s in AUTO_ORDER if stack_refusal(s, servers) is None)


def video_native(choice: str, servers: Sequence[IceServer] = ()) -> bool:
    """Whether libdatachannel sends the video tracks of an offer asking for them.

    With ``native``, and with ``auto`` or ``reactor`` where libdatachannel-py imports
    and reaches every ICE server (the reactor stack answers data channels only).
    """
    if choice == "aiortc":
        return False
    return stack_refusal("native", servers) is None
