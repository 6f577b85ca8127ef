"""The error of a listener that cannot bind its address, and how it words the address.

``GraphServer.serve`` raises ``ListenError`` for the WebSocket, TCP and UDP
listeners; ``rwt serve`` raises it for the HTTP video server too, and prints its
text as one line (docs/cli.md).
"""

from __future__ import annotations

import os

from rwt_protocol.errors import TransportError

__all__ = ["ListenError", "host_port", "os_reason"]


class ListenError(TransportError, OSError):
    """A listener could not bind its address: the message names it, the address and why.

    Also an ``OSError`` (what ``serve`` raised before, and what a failed bind is),
    with the cause's ``errno`` and ``strerror``.

    Args:
        listener: what was listening, ``WebSocket``, ``TCP``, ``UDP``, ``HTTP video``.
        host: the address it tried to bind.
        port: the port it tried to bind.
        cause: the bind's error.

    Attributes:
        listener: as given.
        host: as given.
        port: as given.
    """

    def __init__(self, listener: str, host: str, port: int, cause: OSError) -> None:
        super().__init__(
            f"cannot listen for {listener} on {host_port(host, port)}: {os_reason(cause)}"
        )
        self.errno = cause.errno
        self.strerror = cause.strerror
        self.listener = listener
        self.host = host
        self.port = port

    def __str__(self) -> str:
        # OSError words itself "[Errno 98] Address already in use" once errno is set
        return self.message


def host_port(host: str, port: int) -> str:
    """``HOST:PORT``, with an IPv6 address in brackets."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def os_reason(exc: OSError) -> str:
    """Why ``exc`` happened, as ``address already in use``, without errno or call details."""
    # asyncio words a failed bind as "error while attempting to bind on address ...":
    # the errno's own text is the part a user needs.
    if exc.errno is not None and exc.errno > 0:
        text = os.strerror(exc.errno)
    else:  # getaddrinfo errors have negative codes and their own text
        text = exc.strerror or str(exc) or type(exc).__name__
    return text[:1].lower() + text[1:]
