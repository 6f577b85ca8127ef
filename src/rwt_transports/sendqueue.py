"""How much a socket's kernel still holds for its peer: progress a writer cannot see.

A connection's writer learns that its peer reads only when a send completes, and
the kernel wakes a blocked writer only once about half of the socket's send
buffer is free again. Linux grows that buffer up to 4 MiB by default
(``net.ipv4.tcp_wmem``), which is some 13 camera frames of 300 KB: a viewer
drawing 3 of them a second frees half of it in over 2 s, and looks to input
backpressure as if it had stalled (``rwt_protocol.runtime.flow.INPUT_STALL_S``), though it reads
all the while. The send queue's length (``SIOCOUTQ``: bytes not yet
acknowledged by the peer) shrinks with every read, so a wait that saw no send
complete asks it before calling the peer stalled (``holding.wait_for``).
"""

from __future__ import annotations

import socket
import struct
import sys
from typing import TYPE_CHECKING

from anyio.abc import SocketAttribute

if TYPE_CHECKING:
    from anyio import TypedAttributeProvider

__all__ = ["stream_unsent_bytes", "unsent_bytes"]

if sys.platform.startswith("linux"):
    import fcntl
    import termios

    _SIOCOUTQ: int | None = termios.TIOCOUTQ  # the same request on Linux sockets
else:  # no such request, or no fcntl (Windows)
    _SIOCOUTQ = None


def unsent_bytes(sock: socket.socket) -> int | None:
    """Bytes in ``sock``'s send queue not yet acknowledged by the peer.

    Returns None where that cannot be told: not Linux, not a TCP or Unix
    stream socket, or a closed one.
    """
    if _SIOCOUTQ is None or sock.fileno() < 0 or sock.type != socket.SOCK_STREAM:
        return None
    try:
        raw = fcntl.ioctl(sock.fileno(), _SIOCOUTQ, b"\0\0\0\0")
    except OSError:
        return None
    count: int = struct.unpack("i", raw)[0]
    return count


def stream_unsent_bytes(stream: TypedAttributeProvider) -> int | None:
    """``unsent_bytes`` of an anyio stream's socket (plain or TLS); None without one."""
    sock = stream.extra(SocketAttribute.raw_socket, None)
    return None if sock is None else unsent_bytes(sock)
