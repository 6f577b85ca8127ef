"""One op as the bytes or text on the wire, and back (spec 3.1, D21).

- ``json``: JSON frames to op models and op models to frames, the ``publish``
  fast path, the nesting bound shared with CBOR;
- ``cbor``: CBOR frames, with RFC 8746 typed arrays;
- ``png``: an op's JSON text packed into the pixels of a PNG image (spec 3.1.2).

A codec knows one op at a time: splitting a message into parts is ``framing``'s,
choosing an encoding for a subscriber is ``server.encoding``'s.
"""
