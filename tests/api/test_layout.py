"""The house's rules that a reading of the code checks (docs/architecture.md).

Each rule here is a fact of the source, read with ``ast``: which module imports
what, how many modules a package holds at one level. The import contracts in
pyproject.toml (``lint-imports``) check the layers; these check what a contract
cannot say.
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests.support.packages import SRC

TRANSPORTS = SRC / "rwt_transports"

SERVER_OWN = {"server.py", "config.py", "frontends_registry.py"}
"""The server's own modules: the only ones that may know the server and rosbridge's settings."""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> set[str]:
    """Every module and ``module.name`` that ``path`` imports, type-only ones included.

    Relative imports are made absolute, so ``from .server import X`` gives
    ``rwt_transports.server`` and ``rwt_transports.server.X``.
    """
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*parent, base] if base else parent)
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def front_end_modules() -> list[Path]:
    """The modules of the front ends and the transports below the server.

    Every module of ``rwt_transports`` but the server's own (``SERVER_OWN``), and the
    front ends' own packages (``rwt_http``, ``rwt_mcp``, ``rwt_foxglove``).
    """
    paths = [
        p
        for p in TRANSPORTS.rglob("*.py")
        if p.relative_to(TRANSPORTS).as_posix() not in SERVER_OWN
    ]
    for package in ("rwt_http", "rwt_mcp", "rwt_foxglove"):
        paths += (SRC / package).rglob("*.py")
    return sorted(paths)


def test_no_front_end_knows_the_server_or_rosbridge_settings() -> None:
    """A front end is written against ``rwt_transports.host.FrontEndHost``, not the server."""
    found = {
        str(path.relative_to(SRC)): sorted(
            name
            for name in imports_of(path)
            if name == "rwt_transports.server"
            or name.startswith("rwt_transports.server.")
            or name.endswith(".SessionConfig")
        )
        for path in front_end_modules()
    }
    assert {path: names for path, names in found.items() if names} == {}


def test_the_server_package_keeps_its_top_level_small() -> None:
    """At most 25 modules at ``rwt_transports``' top level: the rest live in its rooms.

    The server, the pump, the channel, the stream transports, the registry and what
    they share stay; WebRTC, the HTTP front ends, UDP, admission, the workers and the
    process's tuning are rooms (sub-packages), each mapped by its docstring.
    """
    assert len(list(TRANSPORTS.glob("*.py"))) <= 25


def test_the_mcp_session_keeps_no_clock_deadline_or_call_book_of_its_own() -> None:
    """``rwt_mcp.session`` is wholly on the runtime (D74): its time comes from its
    transport, its deadlines are the session's timers, its calls the runtime's book."""
    tree = ast.parse((SRC / "rwt_mcp" / "session.py").read_text(encoding="utf-8"))
    names = {
        node.attr if isinstance(node, ast.Attribute) else node.id
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute | ast.Name)
    }
    assert "time" not in imports_of(SRC / "rwt_mcp" / "session.py")
    assert names & {"monotonic", "fail_after", "move_on_after", "sleep", "_calls"} == set()


def test_the_session_contract_is_narrow_and_the_session_base_small() -> None:
    """What the pump drives is at most 28 members (counts and gauges one ``stats``,
    jobs one ``jobs``, the lossy lane an optional ``LossySession``); ``SessionBase``
    is at most 450 lines, made of its sender, jobs and lifecycle."""
    contract = SRC / "rwt_protocol" / "runtime" / "contract.py"
    tree = ast.parse(contract.read_text(encoding="utf-8"))
    [session] = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "ServerSession"]
    members = [
        node.name if isinstance(node, ast.FunctionDef) else ast.unparse(node.target)
        for node in session.body
        if isinstance(node, ast.FunctionDef | ast.AnnAssign)
    ]
    assert len(members) == len(set(members)) <= 28
    connection = SRC / "rwt_protocol" / "runtime" / "connection.py"
    assert len(connection.read_text(encoding="utf-8").splitlines()) <= 450


TRANSPORTS_SPEAKING_NO_PROTOCOL = [
    TRANSPORTS / "pump.py",
    TRANSPORTS / "websocket.py",
    TRANSPORTS / "workers" / "placement.py",
    *sorted((TRANSPORTS / "webrtc").glob("*.py")),
]
"""The modules that carry any protocol's frames and know none (docs/architecture.md)."""


def test_the_transports_name_no_protocol() -> None:
    """No ``"rosbridge"`` default, no ``fragment_datagrams``, no ``PLACED_OPS``: what a
    transport needs of a front end's frames is its hook (``FrontEnd.first_topic``,
    ``split_text``; rosbridge's are ``rwt_transports.rosbridge``'s)."""
    found = []
    for path in TRANSPORTS_SPEAKING_NO_PROTOCOL:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            named = (
                node.id
                if isinstance(node, ast.Name)
                else node.attr
                if isinstance(node, ast.Attribute)
                else node.name
                if isinstance(node, ast.alias)
                else node.value
                if isinstance(node, ast.Constant)
                else None
            )
            if named in ("rosbridge", "fragment_datagrams", "PLACED_OPS"):
                found.append(f"{path.relative_to(SRC)}:{getattr(node, 'lineno', '?')} {named}")
    assert found == []
