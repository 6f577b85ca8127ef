"""How a connection gets in: its turn, its host's share, what it holds before admission.

The server's one admission (``GraphServer.admit``, ``open_session``; docs/limits.md,
"Per server") is built on these. Modules, each importing only those after it:

- ``pending``: what a socket holds before its request is admitted: its bytes
  within the budgets, a count and a turn per host (D58);
- ``arrival``: first input first: a new connection's first frames go before later
  input of others (``Admission``, ``Ticket``);
- ``shares``: the per-host shares of the connection slots (``HostShares``) and how
  addresses group into hosts (``HostPrefixes``: ``--host-prefix-v4``, ``-v6``).
"""
