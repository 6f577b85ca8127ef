"""Which names a calling client may see through rosapi (the hook for access rules).

rosapi answers each call for the client that made it. The server may hand
``install_rosapi`` a function that gives each client a ``Visibility``: one
predicate per name family. Names a predicate refuses are left out of listings,
and lookups treat them as absent (an unknown topic type is ``""``, a hidden
parameter is "not set"). Without it every client sees every name.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rwt_protocol.ports import ClientId

__all__ = ["EVERYTHING", "NameFilter", "Visibility", "VisibilityFor", "is_hidden"]

NameFilter = Callable[[str], bool]
"""Takes a resolved name (``/chatter``; parameters as rosapi names them) and says if it shows."""


@dataclass(frozen=True)
class Visibility:
    """The names one client may see; None in a family means all of them.

    Attributes:
        topics: topic names.
        services: service names (rosapi's own included).
        params: parameter names, ``/node:param`` (ROS 2) or global (ROS 1).
        actions: action names.
        caller: the calling participant, which rosapi sets for each call (the
            parameters a client sets are charged to it, ``parameters.store``).
    """

    topics: NameFilter | None = None
    services: NameFilter | None = None
    params: NameFilter | None = None
    actions: NameFilter | None = None
    caller: ClientId | None = None

    def topic(self, name: str) -> bool:
        """Whether the topic shows."""
        return self.topics is None or self.topics(name)

    def service(self, name: str) -> bool:
        """Whether the service shows."""
        return self.services is None or self.services(name)

    def param(self, name: str) -> bool:
        """Whether the parameter shows."""
        return self.params is None or self.params(name)

    def action(self, name: str) -> bool:
        """Whether the action shows."""
        return self.actions is None or self.actions(name)


EVERYTHING = Visibility()

VisibilityFor = Callable[[ClientId], Visibility]
"""Gives the visibility of a calling client (its participant id)."""


def is_hidden(name: str) -> bool:
    """ROS 2 hides names with a part starting with ``_`` from listings (``/fib/_action/status``)."""
    return any(part.startswith("_") for part in name.split("/"))
