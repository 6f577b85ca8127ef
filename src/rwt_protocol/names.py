"""ROS graph names: resolution for routing (D26).

``chatter``, ``/chatter`` and ``//chatter/`` name one topic; clients still get
every name back in their own spelling, so callers keep the spelling and use the
resolved form only as a key.
"""

from __future__ import annotations

import re

__all__ = ["MAX_NAME_LENGTH", "name_problem", "resolve_name"]


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


#: The longest topic, service, action or parameter name accepted, characters
#: (docs/limits.md; ROS 2 caps a topic name near 255, so real names are far shorter).
MAX_NAME_LENGTH = 1024

_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
# ROS graph resource names (ROS 1 "Names", ROS 2 rcl topic name rules): tokens of
# letters, digits and ``_`` not starting with a digit, separated by ``/``, with an
# optional leading ``/`` or ``~``. Repeated and trailing slashes are tolerated
# because clients send them and resolution drops them (D26).
_GRAPH_NAME = re.compile(rf"(?:~/*|/*){_TOKEN}(?:/+{_TOKEN})*/*", re.ASCII)


def name_problem(name: str) -> str | None:
    """Why ``name`` is not a valid topic, service or action name, or None when it is.

    The rules are ROS's (ROS 1 graph resource names, ROS 2 ``rcl`` topic names):
    ``chatter``, ``/a/b``, ``~private``, ``//a/b/`` pass; ``""``, ``/``, ``a b``,
    ``1a``, ``a-b`` do not. At most ``MAX_NAME_LENGTH`` characters (docs/limits.md).

    Returns:
        A lowercase text for an error status (it never quotes a long name), or None.
    """
    if len(name) > MAX_NAME_LENGTH:
        return f"name longer than {MAX_NAME_LENGTH} characters"
    if _GRAPH_NAME.fullmatch(name) is None:
        shown = name if len(name) <= 40 else name[:37] + "..."
        return (
            f"invalid name {shown!r} (expected ROS name tokens of letters, digits"
            " and _, not starting with a digit, separated by /)"
        )
    return None
