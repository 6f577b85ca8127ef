"""The server runtime: transports (WebSocket, TCP, UDP, stdio, memory) and ``RosbridgeServer``.

The ``rwt`` command line that starts it lives in ``rwt_cli``, above this package.
"""
