"""Sans-IO core of the rosbridge v2 protocol: op models, codecs and the session.

Imports nothing from ``rwt_graph`` or ``rwt_transports`` and does no I/O.
"""
