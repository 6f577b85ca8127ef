"""A server embedded in a program gets ``rwt.ListenError`` for an address in use.

The library raises it (not only the command line, which prints its text as one
line: tests/cli/test_cli_usage.py); it is an ``RwtError`` and, as a failed
bind is, an ``OSError``, so code that caught ``OSError`` keeps working.
"""

from __future__ import annotations

import errno
from typing import TYPE_CHECKING

import anyio
import pytest

import rwt

if TYPE_CHECKING:
    pass


def _serve(config: rwt.ServerConfig) -> rwt.ListenError:
    server = rwt.RosbridgeServer(rwt.Graph(), config)
    with pytest.raises(rwt.ListenError) as caught:
        anyio.run(server.serve)  # fails before it listens: nothing to stop
    return caught.value


@pytest.mark.parametrize("listener", ["WebSocket", "TCP"])
def test_a_stream_port_in_use_is_a_listen_error_naming_it(
    listener: str, taken_tcp_port: int
) -> None:
    if listener == "WebSocket":
        config = rwt.ServerConfig(host="127.0.0.1", port=taken_tcp_port)
    else:
        config = rwt.ServerConfig(host="127.0.0.1", port=0, tcp_port=taken_tcp_port)
    error = _serve(config)
    assert str(error) == (
        f"cannot listen for {listener} on 127.0.0.1:{taken_tcp_port}: address already in use"
    )
    assert (error.listener, error.host, error.port) == (listener, "127.0.0.1", taken_tcp_port)


def test_a_udp_port_in_use_is_a_listen_error_and_an_os_error(taken_udp_port: int) -> None:
    error = _serve(rwt.ServerConfig(host="127.0.0.1", port=None, udp_port=taken_udp_port))
    assert f"UDP on 127.0.0.1:{taken_udp_port}" in str(error)
    assert isinstance(error, rwt.TransportError) and isinstance(error, rwt.RwtError)
    assert isinstance(error, OSError) and error.errno == errno.EADDRINUSE
