"""The link from the graph to a session that advertised services or actions.

It implements ``ServiceProvider`` and ``ActionProvider``: requests and goals for
this client's services and actions become ``call_service``, ``send_action_goal``
and ``cancel_action_goal`` frames (REF §2.7, §2.15, §2.16).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...levels import StatusLevel
from ...names import resolve_name

if TYPE_CHECKING:
    from ...ops import CallService, CancelActionGoal, SendActionGoal
    from .context import HandlerContext

__all__ = ["ProviderLink"]


class ProviderLink:
    """Forwards the graph's requests to one session's peer, as the graph built them."""

    def __init__(self, session: HandlerContext) -> None:
        self._session = session

    def on_service_request(self, request: CallService) -> None:
        """Send the ``call_service`` op (``id``, ``service``, ``args``).

        Raises:
            GraphError: ``service <name>: provider busy ...``: the requests
                waiting for this peer leave no room (docs/limits.md); the
                caller fails, the provider stays connected.
        """
        self._session.send_request(request, f"service {request.service}")

    def on_service_lost(self, service: str, reason: str) -> None:
        """Warn the peer that its service was taken away (D15)."""
        self._session.holdings.drop_offer("service", resolve_name(service))
        self._session.report(StatusLevel.WARNING, f"advertise_service: {reason}")

    def on_action_goal(self, goal: SendActionGoal) -> None:
        """Send the ``send_action_goal`` op, with ``feedback: true`` (REF §2.15).

        Raises:
            GraphError: ``action <name>: provider busy ...``, as for a service
                request (docs/limits.md); the caller's goal is aborted.
        """
        self._session.send_request(goal, f"action {goal.action}")

    def on_action_cancel(self, cancel: CancelActionGoal) -> None:
        """Send the ``cancel_action_goal`` op (REF §2.16)."""
        self._session.send(cancel)

    def on_action_lost(self, action: str, reason: str) -> None:
        """Warn the peer that its action was taken away (D15)."""
        self._session.holdings.drop_offer("action", resolve_name(action))
        self._session.report(StatusLevel.WARNING, f"advertise_action: {reason}")
