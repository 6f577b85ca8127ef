"""The safety envelope: bounds, rates, dead-man stops and approvals for remote commanders.

What remote clients command (any front end: rosbridge on every transport, Foxglove's
client publish, the HTTP API, MCP's tools, WebRTC data channels) passes one check in
the graph's port before any subscriber sees it (docs/safety.md, D66-D69); the robot's
own side (in-process code, the ROS 2 and Zenoh links) is not bound.

Modules:

- ``rules``: the rules (``SafetyRules``), read from a TOML file with each key's line.
- ``fields``: bounded field paths checked against a message type, and applied to messages.
- ``audit``: one structured log line per event (per episode for what a client repeats)
  and the last events, for the console.
- ``envelope``: ``Envelope``, installed on a graph: the check at the publish point,
  the rate limit, the dead-man and the stops it publishes.
"""
