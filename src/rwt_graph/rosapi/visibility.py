"""Which names a calling client may see through rosapi (the hook for access rules).

rosapi answers each call for the client that made it. The server may hand
``install_rosapi`` a function that gives each client a ``Visibility``
(``rwt_graph.visibility``: the one rule every listing of the graph follows,
built from the access policy with ``Visibility.of``). Names it refuses are
left out of listings, and lookups treat them as absent (an unknown topic type
is ``""``, a hidden parameter is "not set"). Without it every client sees
every name.
"""

from __future__ import annotations

from collections.abc import Callable

from rwt_protocol.ports import ClientId

from ..visibility import EVERYTHING, NameFilter, Visibility

__all__ = ["EVERYTHING", "NameFilter", "Visibility", "VisibilityFor", "is_hidden"]

VisibilityFor = Callable[[ClientId], Visibility]
"""Gives the visibility of a calling client (its participant id)."""


def is_hidden(name: str) -> bool:
    """ROS 2 hides names with a part starting with ``_`` from listings (``/fib/_action/status``)."""
    return name.startswith("_") or "/_" in name  # a part starts with "_"; no split per name
