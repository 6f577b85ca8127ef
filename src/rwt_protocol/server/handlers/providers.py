"""The link from the graph to a session that advertised services or actions.

It implements ``ServiceProvider`` and ``ActionProvider``: requests and goals for
this client's services and actions become ``call_service``, ``send_action_goal``
and ``cancel_action_goal`` frames (REF §2.7, §2.15, §2.16).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...levels import StatusLevel
from ...names import resolve_name
from ...ops import CallService, CancelActionGoal, SendActionGoal

if TYPE_CHECKING:
    from .context import HandlerContext

__all__ = ["ProviderLink"]


class ProviderLink:
    """Forwards the graph's requests to one session's peer."""

    def __init__(self, session: HandlerContext) -> None:
        self._session = session

    def on_service_request(self, request_id: str, service: str, args: dict[str, object]) -> None:
        """Send ``{"op":"call_service","id":...,"service":...,"args":{...}}``.

        Raises:
            GraphError: ``service <name>: provider busy ...``: the requests
                waiting for this peer leave no room (docs/limits.md); the
                caller fails, the provider stays connected.
        """
        self._session.send_request(
            CallService(service=service, args=args, id=request_id), f"service {service}"
        )

    def on_service_lost(self, service: str, reason: str) -> None:
        """Warn the peer that its service was taken away (D15)."""
        self._session.holdings.drop_offer("service", resolve_name(service))
        self._session.report(StatusLevel.WARNING, f"advertise_service: {reason}")

    def on_action_goal(
        self, goal_id: str, action: str, action_type: str, args: dict[str, object]
    ) -> None:
        """Send ``send_action_goal`` with ``feedback: true`` (REF §2.15).

        Raises:
            GraphError: ``action <name>: provider busy ...``, as for a service
                request (docs/limits.md); the caller's goal is aborted.
        """
        self._session.send_request(
            SendActionGoal(
                action=action, action_type=action_type, args=args, id=goal_id, feedback=True
            ),
            f"action {action}",
        )

    def on_action_cancel(self, goal_id: str, action: str) -> None:
        """Send ``cancel_action_goal`` (REF §2.16)."""
        self._session.send(CancelActionGoal(action=action, id=goal_id))

    def on_action_lost(self, action: str, reason: str) -> None:
        """Warn the peer that its action was taken away (D15)."""
        self._session.holdings.drop_offer("action", resolve_name(action))
        self._session.report(StatusLevel.WARNING, f"advertise_action: {reason}")
