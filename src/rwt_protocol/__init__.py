"""Sans-IO core of the rosbridge v2 protocol: op models, codecs, framing and both roles.

Imports nothing from ``rwt_graph`` or ``rwt_transports`` and does no I/O. Its parts,
each a layer that imports only the layers below it (import-linter checks it,
pyproject.toml); each subpackage's docstring lists its modules:

- ``server``: the server role: one connection's session (``server.session.Session``),
  its op handlers, and everything the session holds and decides.
- ``client``: the client role, ``client.ClientSession`` (rwt_client runs it). The
  two roles never import each other.
- ``framing``: cutting and joining: byte streams into frames, WebSocket frames into
  messages, large messages into ``fragment`` ops and back, messages into datagrams.
- ``runtime``: the connection runtime every protocol's server session shares
  (``runtime.connection.SessionBase``, the contract the pump drives, the outbox,
  the per-client rules ``runtime.rules.ClientRules``); it knows no protocol: it
  imports none of ``server``, ``ops``, ``codecs`` or ``framing``.
- ``codecs``: one op as JSON, CBOR or PNG. Beside them, ``auth``: the rosauth MAC,
  which the client computes and the server checks.
- ``ports``: the session's interface to a graph, which ``rwt_graph`` implements;
  its calls take the op models.
- ``ops``: one pydantic model per op.
- The vocabulary every part shares: ``errors`` (the error tree), ``levels``
  (status levels), ``names`` (ROS names), ``qos`` (protocol 2.1.0's QoS profile and
  its rules, D62-D65), ``shortcuts`` (the fast paths' switch),
  ``ratelog`` (log lines a peer can trigger), ``distribution`` (the name rwt
  installs under, and the install hints of its extras), ``version`` (the protocol
  version rwt speaks, ``PROTOCOL_VERSION``).
"""
