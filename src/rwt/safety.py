"""The safety envelope: what remote clients may command (docs/safety.md).

The rules (``SafetyRules`` of ``TopicRule`` and ``CallRule``, read by ``load_rules``
and ``parse_rules``, refused with ``RulesError``), the ``Envelope`` a graph holds
them in (``rwt.Graph(safety=...)``, ``Graph.use_safety``, ``ServerConfig.safety``),
the ``EnvelopeError`` a refused command raises, and its audit trail (``AuditTrail``
of ``SafetyEvent``).

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_graph.safety.audit import AuditTrail, SafetyEvent
    from rwt_graph.safety.envelope import Envelope, EnvelopeError
    from rwt_graph.safety.rules import (
        CallRule,
        RulesError,
        SafetyRules,
        TopicRule,
        load_rules,
        parse_rules,
    )

__all__ = [
    "AuditTrail",
    "CallRule",
    "Envelope",
    "EnvelopeError",
    "RulesError",
    "SafetyEvent",
    "SafetyRules",
    "TopicRule",
    "load_rules",
    "parse_rules",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
