"""Which names a client may see: one rule for every listing of the graph.

A server's access rules (``rwt_protocol.runtime.access.AccessPolicy``, the
``--*-glob`` options) decide which topics, services, parameters and actions a
client may use; a client sees no more than that. ``Visibility`` is that rule
for listings, built once from the policy (``Visibility.of``) and shared by
every front end that lists the graph: rosapi's services (``rwt_graph.rosapi``,
one per calling client through its ``VisibilityFor`` hook) and a Foxglove
client's channels, services and connection graph (``rwt_foxglove``), which
ask it of each change of the graph's feed (``sees``). Checking an op against
the rules stays the session's (``AccessPolicy.check``).

A listing may also leave out rwt's own plumbing (``plumbing`` false): the
entities of the server's own nodes (``rwt_graph.nodes.Role.PLUMBING``), so those
nodes too. rosapi shows it, as rosbridge_suite does; a Foxglove client does not
unless the server is told to (docs/foxglove.md, ``--foxglove-show-plumbing``).
What a client connection holds (a robot whose program is a rosbridge client, a
web page's publisher) is never plumbing: it shows, with its node, in every
listing (D47).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_protocol.runtime.access import Family

from .feed import EntityKind
from .nodes import Role

if TYPE_CHECKING:
    from rwt_protocol.ports import ClientId
    from rwt_protocol.runtime.access import AccessPolicy

    from .feed import GraphChange

__all__ = ["EVERYTHING", "NameFilter", "Visibility"]

NameFilter = Callable[[str], bool]
"""Takes a resolved name (``/chatter``; parameters as rosapi names them) and says if it shows."""


@dataclass(frozen=True)
class Visibility:
    """The names a client may see; None in a family means all of them.

    Attributes:
        topics: topic names.
        services: service names (rosapi's own included).
        params: parameter names, ``/node:param`` (ROS 2) or global (ROS 1).
        actions: action names.
        caller: the calling participant, which rosapi sets for each call (the
            parameters a client sets are charged to it, ``parameters.store``).
        plumbing: whether rwt's own helpers show (``Role.PLUMBING``: rosapi's
            services, ``/client_count``, ``/connected_clients``, the TF
            republisher's action, service and topics), and so their nodes; other
            connections' entities and nodes show either way (D47).
    """

    topics: NameFilter | None = None
    services: NameFilter | None = None
    params: NameFilter | None = None
    actions: NameFilter | None = None
    caller: ClientId | None = None
    plumbing: bool = True

    @classmethod
    def of(cls, policy: AccessPolicy) -> Visibility:
        """What a client under ``policy`` may see: what it may use (``AccessPolicy.allows``).

        rosapi's own services show whatever the service patterns say, as a
        client may call them (docs/server.md, access rules). An unrestricted
        policy shows everything (``EVERYTHING``).
        """
        if not policy.restricted:
            return EVERYTHING

        def allowed(family: Family) -> NameFilter:
            return lambda name: policy.allows(family, name)

        return cls(
            topics=allowed(Family.TOPICS),
            services=allowed(Family.SERVICES),
            params=allowed(Family.PARAMS),
            actions=allowed(Family.ACTIONS),
        )

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

    def sees(self, change: GraphChange) -> bool:
        """Whether the entity of a change of the graph's feed shows (by its kind's family).

        rwt's plumbing shows only with ``plumbing``, whatever its name.
        """
        if not self.plumbing and change.role is Role.PLUMBING:
            return False
        kind = change.kind
        if kind is EntityKind.SERVICE:
            return self.service(change.name)
        if kind is EntityKind.ACTION:
            return self.action(change.name)
        return self.topic(change.name)


EVERYTHING = Visibility()
"""Every name shows (no access rules), rwt's plumbing included."""
