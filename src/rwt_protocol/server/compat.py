"""Drop-in behaviour for clients written against rosbridge_suite (docs/differences.md).

rwt's own texts and statuses are the default (docs/decisions.md, D1-D4). With
``Compat.ROSBRIDGE`` (``--compat rosbridge``) a connection behaves as rosbridge_suite
2.1.0 does where a client can tell:

- it gets no ``status`` op until it asks for one with ``set_level``: rosbridge_suite
  sends none, and roslibpy 2.1.0, which has no handler for ``status``, logs a
  traceback for each (docs/reference-behaviour.md, ``set_level`` / ``status``);
- a failure reply (``service_response`` or ``action_result`` with ``result: false``)
  carries rosbridge_suite's text where it has one of its own
  (``Service /x does not exist``, docs/reference-behaviour.md, ``call_service``),
  also when the call first waited for a link to discover the service (``late_reply_text``).

The reply is sent in both modes (D4): rosbridge_suite answers a missing service too.

``Compat.ROSBRIDGE_2_1`` (``--compat rosbridge-2.1``) is ``Compat.ROSBRIDGE`` plus
rosbridge_suite 2.1.0's ``publish``: a ``publish`` carrying ``type`` does not advertise
the topic (D48; it does from rosbridge_suite 2.6.0, 3.2.0 and 4.1.0,
docs/reference-behaviour.md §13.3), so one to a topic the graph does not know is refused,
and no ``qos`` is read (protocol 2.1.0's, which 2.1.0 of the suite does not know): it is
an unknown field, ignored whatever it holds, a malformed one too (D62).
"""

from __future__ import annotations

from enum import StrEnum

from ..errors import RwtError, UnknownNameError
from ..levels import StatusLevel

__all__ = ["Compat", "initial_status_level", "late_reply_text", "reply_text"]


class Compat(StrEnum):
    """Whose behaviour a connection follows where rwt and rosbridge_suite differ."""

    RWT = "rwt"
    """rwt's own texts and statuses (docs/decisions.md)."""
    ROSBRIDGE = "rosbridge"
    """rosbridge_suite 2.1.0's, for clients that match its texts or choke on ``status``."""
    ROSBRIDGE_2_1 = "rosbridge-2.1"
    """``ROSBRIDGE``, and a ``publish`` with ``type`` never advertises (rosbridge_suite 2.1.0)."""

    @property
    def rosbridge(self) -> bool:
        """Whether the connection takes rosbridge_suite's texts and statuses."""
        return self is not Compat.RWT

    @property
    def publish_advertises(self) -> bool:
        """Whether a ``publish`` with ``type`` advertises its topic for the client (D48).

        False for ``ROSBRIDGE_2_1`` only: rosbridge_suite before 2.6.0, 3.2.0 and
        4.1.0 reads no ``type`` on ``publish`` (docs/reference-behaviour.md §13.3).
        """
        return self is not Compat.ROSBRIDGE_2_1

    @property
    def reads_qos(self) -> bool:
        """Whether an op's ``qos`` (protocol 2.1.0) is honoured (D62).

        False for ``ROSBRIDGE_2_1`` only: rosbridge_suite reads it from 2.7.0,
        3.3.0 and 4.2.0 (docs/reference-behaviour.md §13.2).
        """
        return self is not Compat.ROSBRIDGE_2_1


def initial_status_level(compat: Compat, configured: StatusLevel) -> StatusLevel:
    """The status level a new connection starts at.

    Args:
        compat: the server's mode.
        configured: ``SessionConfig.status_level`` (``--status-level``).

    Returns:
        ``configured``; ``StatusLevel.NONE`` in the rosbridge modes, so that only a
        client that sent ``set_level`` ever receives a ``status``.
    """
    return StatusLevel.NONE if compat.rosbridge else configured


def reply_text(compat: Compat, error: RwtError) -> str:
    """The ``values`` text of a failure reply to a call or goal refused with ``error``.

    Args:
        compat: the server's mode.
        error: why the call or goal was refused.

    Returns:
        ``error.message``, or in the rosbridge modes rosbridge_suite's text for
        the same refusal where it has one.
    """
    if compat.rosbridge and isinstance(error, UnknownNameError) and error.kind == "service":
        return f"Service {error.name} does not exist"
    return error.message


def late_reply_text(compat: Compat, service: str, values: object) -> object:
    """The ``values`` of a failure reply the graph gave a call to ``service`` later.

    A call to a service nobody offers waits while a link may still discover it
    (``rwt_graph.services``); when the wait ends without it, the graph answers
    ``UnknownNameError``'s text, which it has no mode to choose by.

    Args:
        compat: the server's mode.
        service: the service as the call named it (without ``#id``).
        values: what the graph answered.

    Returns:
        ``values``, or in the rosbridge modes rosbridge_suite's text when
        ``values`` is the missing service's text.
    """
    missing = UnknownNameError("service", service)
    if compat.rosbridge and values == missing.message:
        return reply_text(compat, missing)
    return values
