"""Find the fenced code blocks of the repository's Markdown files, and what they need.

Rules (docs/README.md, "Code blocks"): ``python`` blocks run to completion,
``bash`` blocks run line by line, ``json`` blocks parse, ``text`` blocks are
output or diagrams. No other fence is allowed, so nothing escapes the test.
A block may be preceded by ``<!-- docs-test: start CMD -->``: CMD (a server)
is started before the block runs, waited for until it prints ``listening on``,
and stopped after it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

LANGUAGES = ("python", "bash", "json", "text")

_FENCE = re.compile(r"^```(\S*)\s*$")
_START = re.compile(r"<!--\s*docs-test:\s*start\s+(.+?)\s*-->")


@dataclass(frozen=True)
class Block:
    """One fenced block: where it is, its fence language, its text and its server."""

    path: Path
    line: int
    language: str
    text: str
    start: str | None

    @property
    def name(self) -> str:
        """``docs/client.md:12``, the test id."""
        return f"{self.path.relative_to(REPO)}:{self.line}"


def markdown_files() -> list[Path]:
    """Every Markdown file a user reads: READMEs, docs/ and the benchmarks' journal.

    Not other projects' READMEs: installed packages (node_modules, a virtualenv
    such as ``.venv`` in the clone) and hidden directories are skipped.
    """
    files = [*REPO.glob("*.md"), *REPO.glob("docs/**/*.md"), *REPO.glob("benchmarks/*.md")]
    files += [p for p in REPO.glob("*/**/README.md") if _ours(p.relative_to(REPO))]
    return sorted(set(files))


def _ours(path: Path) -> bool:
    if any(part.startswith(".") or part in _NOT_OURS for part in path.parts):
        return False
    return not any((REPO / parent / "pyvenv.cfg").exists() for parent in path.parents)


_NOT_OURS = frozenset({"node_modules", "site-packages"})


def blocks_of(path: Path) -> list[Block]:
    """The fenced blocks of one Markdown file, in order."""
    out: list[Block] = []
    lines = path.read_text("utf-8").splitlines()
    start: str | None = None
    index = 0
    while index < len(lines):
        line = lines[index]
        directive = _START.search(line)
        if directive:
            start = directive.group(1)
        fence = _FENCE.match(line)
        if fence is None:
            index += 1
            continue
        body: list[str] = []
        index += 1
        while index < len(lines) and not lines[index].startswith("```"):
            body.append(lines[index])
            index += 1
        out.append(Block(path, index - len(body), fence.group(1), "\n".join(body) + "\n", start))
        start = None
        index += 1
    return out


def bash_commands(text: str) -> list[str]:
    """The commands of a bash block: comments dropped, ``\\`` continuations joined."""
    commands: list[str] = []
    pending = ""
    for raw in text.splitlines():
        line = raw.strip()
        if not pending and (not line or line.startswith("#")):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        commands.append(_strip_comment(pending + line))
        pending = ""
    return commands


def _strip_comment(command: str) -> str:
    # a `#` after whitespace outside quotes starts a comment
    quote = ""
    for i, char in enumerate(command):
        if char in "'\"" and (not quote or quote == char):
            quote = "" if quote else char
        elif char == "#" and not quote and i > 0 and command[i - 1] == " ":
            return command[:i].rstrip()
    return command
