"""No module outside the connection runtime reaches into a session's outbox or watch.

Every protocol queues through ``SessionBase.send_frames`` and ``queue_run``
(docs/architecture.md, "How to add a protocol"), which apply the slow-consumer
rule, the memory budget and the wake-up once for all; a front end that pushed
into the outbox itself would skip them. So ``_outbox`` and ``_watch`` (the
session's), and the private members of ``Outbox`` and ``SlowConsumerWatch``, are
named only inside ``rwt_protocol.runtime``; what others need to read is public
(``SessionBase.outbox``, the outbox's counts).
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests.support.packages import SRC

RUNTIME = SRC / "rwt_protocol" / "runtime"
SESSION_PRIVATES = {"_outbox", "_watch"}


def _privates_of(path: Path, *classes: str) -> set[str]:
    """The private attributes (``self._x``) the methods of ``classes`` in ``path`` use."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and node.name in classes:
            for inner in ast.walk(node):
                if (
                    isinstance(inner, ast.Attribute)
                    and isinstance(inner.value, ast.Name)
                    and inner.value.id == "self"
                    and inner.attr.startswith("_")
                    and not inner.attr.startswith("__")
                ):
                    names.add(inner.attr)
    return names


def _session_classes(tree: ast.Module) -> list[ast.ClassDef]:
    """The classes of a module that are sessions (a base named ``SessionBase`` or ``Session``)."""
    return [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.ClassDef)
        and any(ast.unparse(base).endswith(("SessionBase", "Session")) for base in node.bases)
    ]


def _reaches(path: Path, kept: set[str]) -> list[str]:
    """``file:line attr`` of each reach into a session's outbox or watch.

    ``_outbox`` or ``_watch`` of another object (``session._outbox``), or of
    ``self`` in a session subclass; a private member of ``Outbox`` or
    ``SlowConsumerWatch`` on an outbox or watch (``outbox._held_frames``).
    """
    tree = ast.parse(path.read_text(encoding="utf-8"))
    in_sessions = {id(inner) for cls in _session_classes(tree) for inner in ast.walk(cls)}
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        owner = ast.unparse(node.value)
        if node.attr in SESSION_PRIVATES:
            hit = owner != "self" or id(node) in in_sessions
        else:
            hit = node.attr in kept and owner.endswith(("outbox", "watch"))
        if hit:
            found.append(f"{path.relative_to(SRC)}:{node.lineno} {owner}.{node.attr}")
    return found


def test_the_privates_are_known() -> None:
    kept = _privates_of(RUNTIME / "outbox.py", "Outbox")
    assert {"_held_frames", "_bytes"} <= kept
    assert "_told_slow" in _privates_of(RUNTIME / "backpressure.py", "SlowConsumerWatch")


def test_no_module_outside_the_runtime_reaches_into_the_outbox_or_the_watch() -> None:
    kept = _privates_of(RUNTIME / "outbox.py", "Outbox") | _privates_of(
        RUNTIME / "backpressure.py", "SlowConsumerWatch"
    )
    outside = [p for p in sorted(SRC.rglob("*.py")) if RUNTIME not in p.parents]
    assert outside
    found = [hit for path in outside for hit in _reaches(path, kept)]
    assert found == []
