"""ROS graph names: resolution for routing (PROTOCOL-DECISIONS D26).

``chatter``, ``/chatter`` and ``//chatter/`` name one topic; clients still get
every name back in their own spelling, so callers keep the spelling and use the
resolved form only as a key.
"""

from __future__ import annotations

__all__ = ["resolve_name"]


def resolve_name(name: str) -> str:
    """Resolve a topic, service or action name to its absolute form.

    Relative names resolve against the root namespace (the server node lives at
    ``/``, REF §2.6 step 3); repeated and trailing slashes are dropped.

    Args:
        name: the name as the client wrote it.

    Returns:
        The absolute name, ``"/a/b"``; ``"/"`` for an empty or all-slash name.
    """
    if name.startswith("/") and "//" not in name and not name.endswith("/"):
        return name
    parts = [part for part in name.split("/") if part]
    return "/" + "/".join(parts)
