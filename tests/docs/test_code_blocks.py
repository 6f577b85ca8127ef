"""Every code block of the README and docs/ runs (docs/README.md, "Code blocks").

The README's blocks run as a user types them: ``rwt`` is the installed command, each
``python`` a new interpreter. The blocks of docs/ run ``rwt`` and ``python SCRIPT`` (or
``-c``) through this worker's warm ``rwt`` (tests/support/zygote.py): the same commands
in the same processes' stdio and environment, without paying Python's and rwt's start
each time (about 0.4 s of CPU a command, 60 of them).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import threading
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import trustme

from rwt_protocol.distribution import DISTRIBUTION
from tests.support.ros_mcp import ros_mcp_python
from tests.support.warm import PYTHON, WARM_RWT

from .blocks import LANGUAGES, REPO, Block, bash_commands, blocks_of, markdown_files

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text("utf-8"))

BLOCKS = [block for path in markdown_files() for block in blocks_of(path)]
RUNNABLE = [b for b in BLOCKS if b.language in ("python", "bash", "json")]
CI_RUN = (REPO / ".ci" / "run").read_text("utf-8").splitlines()

NAMED_PORTS = (9090, 9091, 9092, 8080, 8765, 7447)
"""The ports the docs name. A block runs with each on a free port instead: the README's
first quick-start line (``rwt serve``, on 9090) may be serving while the suite runs."""
_NAMED = re.compile(r"(?<!\d)(" + "|".join(map(str, NAMED_PORTS)) + r")(?!\d)")

Ports = dict[str, str]


def _free_ports() -> Ports:
    """A free TCP port on 127.0.0.1 for each named port (UDP's 9092 is free there too)."""
    found: Ports = {}
    sockets = []
    try:
        for named in NAMED_PORTS:  # held together, so no two come out the same
            sock = socket.socket()
            sockets.append(sock)
            sock.bind(("127.0.0.1", 0))
            found[str(named)] = str(sock.getsockname()[1])
    finally:
        for sock in sockets:
            sock.close()
    return found


def _on_free_ports(text: str, ports: Ports) -> str:
    """``text`` with every named port replaced by its free one."""
    return _NAMED.sub(lambda match: ports[match.group(1)], text)


def _server_on_free_port(command: str, ports: Ports) -> str:
    """A server command that names no port gets the free port of its default, 9090.

    ``rwt serve`` takes ``--port``; an example takes the port as its first argument
    (``sys.argv[1]``) or ``--port``.
    """
    command = _on_free_ports(command, ports)
    words = shlex.split(command)
    port = ports["9090"]
    if words[:2] == ["rwt", "serve"]:
        named = any(w == "--port" or w.startswith("--port=") for w in words)
        return command if named else f"{command} --port {port}"
    if words[:1] == ["python"] and len(words) == 2 and words[1].startswith("examples/"):
        source = (REPO / words[1]).read_text("utf-8")
        return f"{command} {port}" if "sys.argv[1]" in source else f"{command} --port {port}"
    return command


def test_every_block_has_a_known_language() -> None:
    unknown = [f"{b.name} ({b.language or 'no language'})" for b in BLOCKS]
    unknown = [name for name, b in zip(unknown, BLOCKS, strict=True) if b.language not in LANGUAGES]
    assert not unknown, f"fences must be one of {LANGUAGES}: {unknown}"


def test_python_blocks_and_examples_import_only_rwt() -> None:
    """The packages behind ``rwt`` are its implementation: docs show the public API."""
    texts = {b.name: b.text for b in BLOCKS if b.language in ("python", "text")}
    texts |= {str(p.relative_to(REPO)): p.read_text("utf-8") for p in REPO.glob("examples/*.py")}
    private = re.compile(r"^\s*(from|import)\s+rwt_\w+", re.M)
    # a command's inline Python too: python -c "from rwt_... import ..."
    inline = re.compile(r"python3? -c [\"'][^\"']*\b(from|import)\s+rwt_\w+")
    commands = {b.name: b.text for b in BLOCKS if b.language == "bash"}
    assert [name for name, text in texts.items() if private.search(text)] == []
    assert [name for name, text in commands.items() if inline.search(text)] == []


def test_the_readme_has_the_two_quick_start_commands_and_ci_runs_the_second() -> None:
    quick = blocks_of(REPO / "README.md")[0]
    serve, test = bash_commands(quick.text)
    assert serve.endswith("&& rwt serve")
    assert test in CI_RUN  # .ci/run runs the README's test command verbatim


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with what the docs' commands name: cert.pem, key.pem, secret.txt."""
    path = tmp_path_factory.mktemp("docs")
    authority = trustme.CA()
    cert = authority.issue_cert("127.0.0.1", "localhost")
    cert.private_key_pem.write_to_path(str(path / "key.pem"))
    cert.cert_chain_pems[0].write_to_path(str(path / "cert.pem"))
    (path / "secret.txt").write_text("a-secret-of-sixteen-chars\n")
    for name in ("examples", "benchmarks", "conformance", "src", "tests", "pyproject.toml"):
        (path / name).symlink_to(REPO / name)
    return path


@pytest.fixture(scope="module")
def warm_bin(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder whose ``rwt`` and ``python SCRIPT``/``python -c`` run warm (first on PATH)."""
    path = tmp_path_factory.mktemp("warm-bin")
    python, warm = shlex.quote(sys.executable), shlex.quote(str(WARM_RWT))
    commands = {
        "rwt": f'exec {python} -S {warm} "$@"\n',
        # what the warm runs take; anything else (-m pip ...) is the interpreter itself
        "python": f'case "$1" in -c|*.py) exec {python} -S {warm} --python "$@";; esac\n'
        f'exec {python} "$@"\n',
    }
    for name, body in commands.items():
        (path / name).write_text(f"#!/bin/sh\n{body}", "utf-8")
        (path / name).chmod(0o755)
    return path


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "src"), str(REPO)])
    env["PYTHONUNBUFFERED"] = "1"
    return env


@contextmanager
def _running(command: str, cwd: Path) -> Iterator[str]:
    """Start ``command``, wait for its ``listening on`` line, stop it afterwards.

    Its stderr goes to a file and its stdout is drained by a thread: a server
    that logs every connection must never block on a full pipe.
    """
    log = cwd / "server.log"
    with log.open("w") as stderr:
        process = subprocess.Popen(
            ["bash", "-c", f"exec {command}"],
            cwd=cwd,
            env=_env(),
            stdout=subprocess.PIPE,
            stderr=stderr,
            text=True,
            start_new_session=True,
        )
    assert process.stdout is not None
    seen: list[str] = []
    drain: threading.Thread | None = None
    try:
        for line in process.stdout:
            seen.append(line)
            if "listening on" in line:
                break
        else:
            pytest.fail(f"{command!r} exited without listening: {log.read_text()[-2000:]}")
        drain = threading.Thread(target=process.stdout.read, daemon=True)
        drain.start()
        yield "".join(seen)
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
        if drain is not None:
            drain.join(timeout=5)
        process.stdout.close()
        assert "Traceback" not in log.read_text(), log.read_text()[-4000:]


def _run(command: str, cwd: Path, ports: Ports) -> None:
    """Run one command of a bash block, as a user would type it (on free ports)."""
    if command in CI_RUN:
        return  # the test command itself: .ci/run runs it (test above), not run again here
    parts = [_on_free_ports(part.strip(), ports) for part in command.split("&&")]
    for part in parts:
        words = shlex.split(part)
        if words[:4] == ["python", "-m", "pip", "install"]:
            # resolve what the user would install (the extras exist), without touching this env
            others = [w for w in words[4:] if not w.startswith("-") and not _ours(w)]
            if others:  # another project's: pip resolves it against the index
                _shell(
                    [sys.executable, "-m", "pip", "install", "--dry-run", "--no-deps", *others],
                    REPO,
                )
        elif words[:2] == ["rwt", "serve"] or (words[:1] == ["python"] and "examples/" in part):
            with _running(_server_on_free_port(part, ports), cwd):
                pass
        else:
            _shell(["bash", "-c", part], cwd)


def _ours(word: str) -> bool:
    """Whether an install line's requirement is this project; if so, its extras must exist.

    ``rwt-rosbridge[zenoh]`` is what PyPI serves once it is released, ``".[server]"``
    this checkout: both are checked against this ``pyproject.toml`` (reading it, not
    building the project's metadata, which pip would do for every line). One naming
    ``rwt``, an unrelated project on PyPI, fails.
    """
    name = re.split(r"[\[=<>~!; ]", word, maxsplit=1)[0]
    extras = re.search(r"\[([^\]]*)\]", word)
    assert name.lower() != "rwt", f"{word!r} installs the PyPI project rwt, not this one"
    if name not in {DISTRIBUTION, "."}:
        return False
    known = set(PYPROJECT["project"]["optional-dependencies"])
    wanted = {e.strip() for e in (extras[1] if extras else "").split(",") if e.strip()}
    assert wanted <= known, f"{word!r}: no extra {sorted(wanted - known)} in pyproject.toml"
    return True


def _shell(args: list[str], cwd: Path) -> None:
    """Run ``args`` to completion; it must exit 0."""
    result = subprocess.run(
        args, check=False, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, f"{args}: {result.stdout[-2000:]}{result.stderr[-2000:]}"


@pytest.mark.parametrize("block", RUNNABLE, ids=[b.name for b in RUNNABLE])
def test_block_runs(
    block: Block, workdir: Path, warm_bin: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    warm = block.path != REPO / "README.md"  # the README's as typed (module docstring)
    if warm:
        monkeypatch.setenv("PATH", f"{warm_bin}{os.pathsep}{os.environ['PATH']}")
    if block.language == "python" and '"ros-mcp"' in block.text:  # its own environment (D52)
        python, why = ros_mcp_python()
        if python is None:
            pytest.skip(f"ros-mcp 3.1.2 cannot run here: {why}")
        only = tmp_path / "ros-mcp-bin"  # its command alone: not its env's python
        only.mkdir()
        (only / "ros-mcp").symlink_to(python.parent / "ros-mcp")
        monkeypatch.setenv("PATH", f"{only}{os.pathsep}{os.environ['PATH']}")
    if block.language == "json":
        try:
            json.loads(block.text)
        except ValueError:
            for line in block.text.splitlines():
                if line.strip():
                    json.loads(line)
        return
    ports = _free_ports()
    start = _server_on_free_port(block.start, ports) if block.start else None
    with _running(start, workdir) if start else _nothing():
        if block.language == "python":
            script = tmp_path / "block.py"
            script.write_text(_on_free_ports(block.text, ports), "utf-8")
            _shell([*(PYTHON if warm else [sys.executable]), str(script)], workdir)
        else:
            for command in bash_commands(block.text):
                _run(command, workdir, ports)


@contextmanager
def _nothing() -> Iterator[None]:
    yield
