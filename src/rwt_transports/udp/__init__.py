"""UDP: one datagram per message, one session per peer address that proved it receives.

Rosbridge over UDP (D22; docs/server.md). Modules, each importing only those after
it:

- ``transport``: the endpoint: ``UdpOptions``, ``serve_udp``, a session per peer on
  the connection pump, its datagrams cut and joined as rosbridge's ``fragment`` ops;
- ``auth``: a peer gets a session with its ``auth`` op, not before (D23, D31);
- ``validation``: a peer proves it receives at its address before it is served
  (a token exchange; what is sent to an unproven address is bounded).
"""
