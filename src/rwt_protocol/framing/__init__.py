"""Cutting and joining: whole frames and messages from the pieces transports carry.

- ``streams``: byte streams (TCP, stdio) into frames (D22);
- ``messages``: WebSocket frames into whole messages (RFC 6455 5.4), both roles;
- ``fragments``: a large message as ``fragment`` or ``png`` parts, both ways
  (spec 3.1.1, D19, D20), and the server-wide budget of incomplete ones;
- ``datagrams``: a message cut into datagram-sized ``fragment`` ops (UDP, D22).
"""
