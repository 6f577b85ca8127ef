"""The safety rules: what remote clients may command, read from a TOML file or built in Python.

A rules file (``rwt serve --safety FILE``, docs/safety.md) holds one ``[[topic]]`` table
per bounded topic and ``[[service]]``/``[[action]]`` tables for calls that need a
person's approval. This module reads its shape: the keys, their types and ranges, and
where each key is (its line), so that a later check against the message types
(``fields``, ``envelope``) can name the line too. It knows no message type.

A file that does not parse, or has a key it does not know, a value of the wrong type
or out of range, or one topic twice, is refused with ``RulesError``, naming the
file and the line (D66).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from rwt_protocol.errors import ConfigError
from rwt_protocol.names import name_problem, resolve_name

if TYPE_CHECKING:
    from collections.abc import Callable

    _Fail = Callable[[str, str], "RulesError"]

__all__ = [
    "APPROVAL_TIMEOUT_S",
    "CallRule",
    "RulesError",
    "SafetyRules",
    "TopicRule",
    "load_rules",
    "parse_rules",
]

APPROVAL_TIMEOUT_S = 60.0
"""Seconds a person has to answer an approval by default (``approval_timeout_s``)."""
MAX_APPROVAL_TIMEOUT_S = 3600.0
"""The longest ``approval_timeout_s`` a file may set (an hour)."""
MAX_RULES = 1024
"""Topic, service and action tables a file may hold together."""

Violation = Literal["clamp", "reject"]

_TOPIC_KEYS = frozenset(
    {"name", "type", "bounds", "on_violation", "max_rate_hz", "deadman_s", "stop", "approval"}
)
_CALL_KEYS = frozenset({"name", "approval"})
_TOP_KEYS = frozenset({"topic", "service", "action", "approval_timeout_s"})


class RulesError(ConfigError):
    """Safety rules that cannot be used; the text names the file and the line (D66).

    Args:
        message: ``FILE line N: what is wrong``, or ``FILE: ...`` where no line is known.
    """


@dataclass(frozen=True)
class TopicRule:
    """What a remote client may publish on one topic (docs/safety.md).

    Attributes:
        name: the topic (resolved: ``/cmd_vel``).
        type: its message type, in any spelling (``geometry_msgs/msg/Twist``).
        bounds: dotted field path (``linear.x``, ``position[0]``, ``position[*]``) ->
            ``(min, max)``, inclusive, in the field's units.
        on_violation: ``clamp`` (the message goes on with the field clamped) or
            ``reject`` (an error, nothing delivered).
        max_rate_hz: commands a second the topic takes from remote clients
            together; None: no limit.
        deadman_s: seconds without a command after which ``stop`` is published;
            None: no dead-man.
        stop: the message published by the dead-man (JSON form), or None.
        approval: an MCP agent's publish waits for a person's yes.
        lines: the line of each key (``bounds.linear.x``, ``stop``) in its file, for errors.
        source: the file it came from (for errors), or "" when built in Python.
    """

    name: str
    type: str
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    on_violation: Violation = "reject"
    max_rate_hz: float | None = None
    deadman_s: float | None = None
    stop: Mapping[str, object] | None = None
    approval: bool = False
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)
    source: str = field(default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        """Resolve the name and refuse a rule that cannot be used, from a file or Python (D66).

        A rule built in Python is held to what a file's is: a name given as ``cmd_vel``
        must bind ``/cmd_vel``, and a dead-man without a stop must not pass unnoticed.

        Raises:
            RulesError: a bad name or type, ``on_violation`` neither ``clamp`` nor
                ``reject``, a rate or a dead-man time that is not a positive number,
                a bound that is not ``(min, max)`` of finite numbers with min <= max,
                ``stop`` that is not a table, ``deadman_s`` without ``stop`` (or the
                reverse), ``approval`` not a bool; the text names the key's line.
        """
        name = _resolved(self.name, "topic", self.source, self.lines)
        object.__setattr__(self, "name", name)
        problem = _topic_problem(self)
        if problem is not None:
            raise RulesError(f"{self.where(problem[0])}: {problem[1]}")
        for key in ("max_rate_hz", "deadman_s"):
            value = getattr(self, key)
            object.__setattr__(self, key, None if value is None else float(value))
        bounds = {path: (float(low), float(high)) for path, (low, high) in self.bounds.items()}
        object.__setattr__(self, "bounds", bounds)

    def where(self, key: str = "") -> str:
        """``FILE line N: /topic`` for the key, for errors.

        A key not found in the text (``bounds.linear.x`` written in an inline table)
        names the line of the nearest key around it (``bounds``), else its table's.
        """
        parts = key.split(".")
        found = (self.lines.get(".".join(parts[:end])) for end in range(len(parts), 0, -1))
        line = next((each for each in found if each), None) or self.lines.get("")
        place = self.source or "safety rules"
        return f"{place} line {line}: {self.name}" if line else f"{place}: {self.name}"


@dataclass(frozen=True)
class CallRule:
    """A service or action an MCP agent calls only with a person's approval.

    Attributes:
        name: the service or action (resolved).
        approval: whether a person must approve each call.
        lines: the line of each key in its file.
        source: the file it came from (for errors), or "" when built in Python.
    """

    name: str
    approval: bool = True
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)
    source: str = field(default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        """Resolve the name (``reset`` is ``/reset``), as ``needs_approval`` compares it.

        Raises:
            RulesError: a bad name, or ``approval`` not a bool.
        """
        object.__setattr__(
            self, "name", _resolved(self.name, "service/action", self.source, self.lines)
        )
        if not isinstance(self.approval, bool):
            where = _at(self.source or "safety rules", self.lines.get("approval"))
            raise RulesError(f"{where}{self.name}: approval: true or false")


@dataclass(frozen=True)
class SafetyRules:
    """Every rule of one envelope (docs/safety.md).

    Attributes:
        topics: one rule per bounded topic.
        services: services whose calls need approval.
        actions: actions whose goals need approval.
        approval_timeout_s: seconds a person has to answer (then: nothing done).
        source: the file the rules came from, for errors ("" when built in Python).
    """

    topics: tuple[TopicRule, ...] = ()
    services: tuple[CallRule, ...] = ()
    actions: tuple[CallRule, ...] = ()
    approval_timeout_s: float = APPROVAL_TIMEOUT_S
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        """Refuse rules that cannot be used together, from a file or Python (D66).

        Raises:
            RulesError: more than ``MAX_RULES`` tables, one topic (service, action)
                twice, or ``approval_timeout_s`` not in (0, 3600].
        """
        source = self.source or "safety rules"
        _at_most(len(self.topics) + len(self.services) + len(self.actions), source)
        for kind, rules in (
            ("topic", self.topics),
            ("service", self.services),
            ("action", self.actions),
        ):
            _no_twice(kind, rules, source)
        if not _timeout_ok(self.approval_timeout_s):
            raise RulesError(f"{source}: {_TIMEOUT_PROBLEM}")
        object.__setattr__(self, "approval_timeout_s", float(self.approval_timeout_s))

    def topic(self, name: str) -> TopicRule | None:
        """The rule of topic ``name`` (any spelling), or None."""
        resolved = resolve_name(name)
        return next((rule for rule in self.topics if rule.name == resolved), None)

    def needs_approval(self, family: str, name: str) -> bool:
        """Whether a call on ``name`` of ``family`` (topics, services, actions) needs a person."""
        resolved = resolve_name(name)
        rules: tuple[TopicRule | CallRule, ...] = ()
        if family == "topics":
            rules = self.topics
        elif family in ("services", "actions"):
            rules = self.services if family == "services" else self.actions
        return any(rule.name == resolved and rule.approval for rule in rules)


def load_rules(path: Path | str) -> SafetyRules:
    """Read a rules file (``parse_rules`` of its text).

    Raises:
        RulesError: it cannot be read, or ``parse_rules`` refuses it.
    """
    source = str(path)
    try:
        text = Path(path).read_text("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.reason if isinstance(exc, UnicodeDecodeError) else exc.strerror
        raise RulesError(f"cannot read {source}: {reason}") from None
    return parse_rules(text, source)


def parse_rules(text: str, source: str = "safety rules") -> SafetyRules:
    """The rules of a TOML text, their shape checked (not yet against message types).

    Args:
        text: the file's text.
        source: its name in errors.

    Raises:
        RulesError: the text is not TOML, or a key, a value or a table is wrong;
            the text names ``source`` and the line.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RulesError(_toml_error(source, str(exc))) from None
    lines = _KeyLines(text)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise RulesError(f"{_at(source, lines.top(unknown[0]))}unknown key {unknown[0]!r}")
    timeout = data.get("approval_timeout_s", APPROVAL_TIMEOUT_S)
    if not _timeout_ok(timeout):
        raise RulesError(f"{_at(source, lines.top('approval_timeout_s'))}{_TIMEOUT_PROBLEM}")
    tables = {kind: _tables(data, kind, source, lines) for kind in ("topic", "service", "action")}
    _at_most(sum(len(each) for each in tables.values()), source)  # before reading them
    topics = tuple(
        _topic(table, source, lines.of("topic", index))
        for index, table in enumerate(tables["topic"])
    )
    services = tuple(
        _call(table, "service", source, lines.of("service", index))
        for index, table in enumerate(tables["service"])
    )
    actions = tuple(
        _call(table, "action", source, lines.of("action", index))
        for index, table in enumerate(tables["action"])
    )
    return SafetyRules(topics, services, actions, timeout, source)


def _tables(
    data: dict[str, object], kind: str, source: str, lines: _KeyLines
) -> list[dict[str, object]]:
    value = data.get(kind, [])
    if not isinstance(value, list) or not all(isinstance(each, dict) for each in value):
        raise RulesError(f"{_at(source, lines.top(kind))}{kind}: tables ([[{kind}]])")
    return value


def _topic(table: dict[str, object], source: str, lines: dict[str, int]) -> TopicRule:
    """One ``[[topic]]`` table: its keys known, its values checked by ``TopicRule``."""
    name = _resolved(table.get("name"), "topic", source, lines)

    def fail(key: str, problem: str) -> RulesError:
        return RulesError(f"{_at(source, lines.get(key) or lines.get(''))}{name}: {problem}")

    _no_unknown(table, _TOPIC_KEYS, fail)
    given: dict[str, Any] = {key: table[key] for key in _TOPIC_KEYS & table.keys()}
    given.update(name=name, type=table.get("type"), lines=lines, source=source)
    return TopicRule(**given)


def _topic_problem(rule: TopicRule) -> tuple[str, str] | None:
    """The first key of ``rule`` that cannot be used, and why; None: none."""
    if not isinstance(rule.type, str) or not rule.type:
        return "type", "type: a message type (pkg/msg/Type) is needed"
    if rule.on_violation not in ("clamp", "reject"):
        return "on_violation", f"on_violation: clamp or reject, not {rule.on_violation!r}"
    for key in ("max_rate_hz", "deadman_s"):
        value = getattr(rule, key)
        if value is not None and not (_number(value) and math.isfinite(value) and value > 0):
            return key, f"{key}: a positive number, not {value!r}"
    if rule.stop is not None and not isinstance(rule.stop, Mapping):
        return "stop", "stop: a table (the message to publish)"
    if rule.deadman_s is not None and rule.stop is None:
        return "deadman_s", "deadman_s needs stop (the message the dead-man publishes)"
    if rule.stop is not None and rule.deadman_s is None:
        return "stop", "stop is the dead-man's message: add deadman_s"
    if not isinstance(rule.approval, bool):
        return "approval", "approval: true or false"
    return _bounds_problem(rule.bounds)


def _bounds_problem(bounds: object) -> tuple[str, str] | None:
    """The first bound that is not ``(min, max)`` of finite numbers, min <= max, and why."""
    if not isinstance(bounds, Mapping):
        return "bounds", "bounds: a table of field = [min, max]"
    for path, pair in bounds.items():
        key = f"bounds.{path}"
        if (
            not isinstance(pair, tuple | list)
            or len(pair) != 2
            or not all(_number(v) for v in pair)
        ):
            return key, f"bounds {path!r}: [min, max], two numbers"
        if not (math.isfinite(pair[0]) and math.isfinite(pair[1])) or pair[0] > pair[1]:
            return key, f"bounds {path!r}: finite numbers with min <= max, not {list(pair)}"
    return None


def _call(table: dict[str, object], kind: str, source: str, lines: dict[str, int]) -> CallRule:
    """One ``[[service]]`` or ``[[action]]`` table."""
    name = _resolved(table.get("name"), kind, source, lines)

    def fail(key: str, problem: str) -> RulesError:
        return RulesError(f"{_at(source, lines.get(key) or lines.get(''))}{name}: {problem}")

    _no_unknown(table, _CALL_KEYS, fail)
    approval: Any = table.get("approval", True)
    return CallRule(name, approval, lines, source)


def _resolved(name: object, kind: str, source: str, lines: Mapping[str, int]) -> str:
    """``name`` resolved (``cmd_vel`` is ``/cmd_vel``), or ``RulesError`` naming its line."""
    where = _at(source or "safety rules", lines.get("name") or lines.get(""))
    if not isinstance(name, str):
        raise RulesError(f"{where}[[{kind}]]: name: a {kind} name is needed")
    problem = name_problem(name)
    if problem is not None:
        raise RulesError(f"{where}[[{kind}]]: name {name!r}: {problem}")
    return resolve_name(name)


def _no_unknown(table: dict[str, object], known: frozenset[str], fail: _Fail) -> None:
    for key in table:
        if key not in known:
            raise fail(key, f"unknown key {key!r} (known: {', '.join(sorted(known))})")


def _no_twice(kind: str, rules: tuple[TopicRule | CallRule, ...], source: str) -> None:
    seen: set[str] = set()
    for rule in rules:
        if rule.name in seen:
            raise RulesError(f"{_at(source, rule.lines.get(''))}{rule.name}: a second [[{kind}]]")
        seen.add(rule.name)


def _at_most(count: int, source: str) -> None:
    if count > MAX_RULES:
        raise RulesError(f"{source}: more than {MAX_RULES} tables")


_TIMEOUT_PROBLEM = "approval_timeout_s: a number of seconds in (0, 3600]"


def _timeout_ok(value: object) -> bool:
    return _number(value) and 0 < value <= MAX_APPROVAL_TIMEOUT_S  # type: ignore[operator]


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _at(source: str, line: int | None) -> str:
    return f"{source} line {line}: " if line else f"{source}: "


_TOML_AT = re.compile(r"\s*\(at line (\d+), column (\d+)\)$")
_TOML_END = re.compile(r"\s*\(at end of document\)$")


def _toml_error(source: str, text: str) -> str:
    """The TOML reader's text, ``Invalid value (at line 3, column 10)``, as ``FILE line 3: ...``."""
    found = _TOML_AT.search(text)
    if found is not None:
        reason = text[: found.start()]
        return f"{source} line {found[1]}: {reason[:1].lower()}{reason[1:]} (column {found[2]})"
    reason = _TOML_END.sub("", text)
    return f"{source}: {reason[:1].lower()}{reason[1:]} (at the end of the file)"


_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?")
_KEY = re.compile(
    r"""^\s*((?:"[^"]*"|'[^']*'|[A-Za-z0-9_-]+)(?:\s*\.\s*(?:"[^"]*"|'[^']*'|[A-Za-z0-9_-]+))*)\s*="""
)
_PART = re.compile(r"""\s*("[^"]*"|'[^']*'|[A-Za-z0-9_-]+)\s*(?:\.|$)""")


class _KeyLines:
    """Where each key of a rules file is: ``of(kind, index)[key]`` is its line (1-based).

    A best effort from the text, for error messages: a table's keys by their
    dotted path within it (``bounds.linear.x``), its header as ``""``. A key
    inside a multi-line value is not found; the error then names its table's line.
    """

    def __init__(self, text: str) -> None:
        self._top: dict[str, int] = {}
        self._tables: dict[tuple[str, int], dict[str, int]] = {}
        counts: dict[str, int] = {}
        current: dict[str, int] = self._top
        prefix = ""
        for number, line in enumerate(text.splitlines(), 1):
            header = _HEADER.match(line)
            if header is not None:
                parts = _parts(header[2])
                if header[1] == "[[" and len(parts) == 1:
                    kind = parts[0]
                    index = counts.get(kind, 0)
                    counts[kind] = index + 1
                    current = self._tables.setdefault((kind, index), {"": number})
                    prefix = ""
                elif parts and (parts[0], counts.get(parts[0], 0) - 1) in self._tables:
                    current = self._tables[(parts[0], counts[parts[0]] - 1)]
                    prefix = ".".join(parts[1:]) + "."
                    current.setdefault(prefix[:-1], number)
                elif parts:  # a top-level table (``[topic]`` for ``[[topic]]``): its header
                    self._top.setdefault(parts[0], number)
                    current, prefix = {}, ""
                continue
            key = _KEY.match(line)
            if key is not None:
                current.setdefault(prefix + ".".join(_parts(key[1])), number)

    def top(self, key: str) -> int | None:
        """The line of a top-level key."""
        return self._top.get(key)

    def of(self, kind: str, index: int) -> dict[str, int]:
        """The lines of the ``index``-th ``[[kind]]`` table's keys."""
        return self._tables.get((kind, index), {})


def _parts(dotted: str) -> list[str]:
    return [part.strip("\"'") for part in _PART.findall(dotted)]
