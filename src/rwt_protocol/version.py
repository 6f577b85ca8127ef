"""The version of the rosbridge protocol rwt speaks, as ``GET /version`` reports it.

The specification is versioned from rosbridge_suite 2.6.0 on, under semantic
versioning (docs/reference-behaviour.md, §13.2): the major number for changes
that break existing clients, the minor for additions (an op, an optional field),
the patch for behaviour changes without new fields.
"""

from __future__ import annotations

from typing import Final

__all__ = ["PROTOCOL_VERSION"]

PROTOCOL_VERSION: Final[tuple[int, int, int]] = (2, 1, 0)
"""The (major, minor, patch) version of the rosbridge protocol rwt answers to.

The spec's version history (docs/reference-behaviour.md §13.2): the unversioned
"rosbridge v2.0" text up to rosbridge_suite 2.5.0; **2.0.0** (2.6.0) numbers it,
lists the ops' fields with their direction and lets a ``publish`` carrying
``type`` advertise its topic (§13.3); **2.1.0** (2.7.0) adds an optional ``qos``
object to ``advertise``, ``publish`` and ``subscribe``. rwt does what 2.1.0 adds: its
``qos`` is read as the reference reads it (``rwt_protocol.ops.qos``) and kept on the
graph and given to the links (D62-D65; docs/reference-behaviour.md §13.7, §13.8).
Where rwt's answers differ from the spec's (statuses, replies to refused ops),
docs/decisions.md says so. Change this only
with the spec's version history, and only once rwt does what that version adds.
"""
