"""The server runtime: transports (WebSocket, TCP, UDP, stdio, WebRTC, memory), the server.

The ``rwt`` command line that starts it lives in ``rwt_cli``, above this package.
"""
