"""The conformance suite as data: requirements and cases, loaded from TOML.

``requirements.toml`` lists one ``[[requirement]]`` per rule: a stable ``id``,
the ``source`` it comes from (spec section, docs/decisions.md ``Dn`` or a
docs/reference-behaviour.md scenario) and a one-line ``statement``; optional
``since`` and ``until`` name the spec versions it holds for (``versions``: ``since <=
version < until``, ``X.Y.Z`` or ``unversioned``; default every version). Each file in
``cases/`` lists ``[[case]]`` tables: an ``id``, the ``requirements`` it checks, a
``title`` and ``steps``, a transcript of frames to send and frames to expect
on one or more connections (``on``, default ``"a"``; other names are peers
that advertise, publish, provide services...).

A step has exactly one action key:

- ``send`` (a table: the op, sent as JSON text), ``send_raw`` (a string sent
  as-is), ``send_binary`` (a table sent as one CBOR item: a binary frame on
  WebSocket, an item in the stream on TCP, D21/D22), ``send_auth`` (a rosauth
  ``auth`` op made with the server's secret, valid from now for 60 s; the
  table may replace ``mac``, ``client``, ``dest``, ``rand`` or ``level``, and
  move ``t``/``end`` with ``t_offset_s``/``end_offset_s`` from now, D23);
- ``expect`` (a pattern, see ``match``; ``count`` asks for that many matching
  frames, ``binary = true`` requires CBOR frames, ``binary = false`` JSON text
  frames), ``expect_status`` (a
  pattern for a ``status`` frame; strict profile only, since rosbridge_suite
  never sends status, REF §1.3), ``expect_none`` (after a ``sync``, no received
  frame may match the pattern);
- ``sync = true`` (a round trip through a private topic: everything the server
  sent this connection before it has arrived), ``open = true``, ``close =
  true`` (connect or disconnect this connection now), ``expect_closed = true``
  (the server closes this connection).

Optional per step: ``profile`` (run only in ``strict`` or only in
``reference``), ``dialect`` (run only against a ``ros1`` or only against a
``ros2`` server: the time spelling ``secs``/``nsecs`` or ``sec``/``nanosec``,
type names ``pkg/Type`` or ``pkg/msg/Type``, rosapi's field names),
``not_in`` (a ``skip`` key or a list of them, such as ``"reference+ros1"``:
left out there, for a step the reference is known to fail), ``timeout_s``,
``repeat`` (run the step N times with ``${i}`` counting from 0), ``pace_s``
(seconds between the repetitions of a repeated step: a paced burst, for a
server that keeps only the last few messages of a burst per topic, REF §5.1),
``in_order`` (an ``expect`` whose frame must be the first received one with the
pattern's ``op`` and ``topic``), ``defect`` and ``unless_defect`` (below).

Where the reference breaks the spec, a case records what it does: steps with
``defect = "REF §12.x"`` (narrowed by ``profile``/``dialect`` to where it applies)
are the reference's way, steps with ``unless_defect = true`` the spec's way they
stand in for. Where a ``defect`` step applies, the runner tries the spec's way
first and, if that fails, the reference's way for each section cited (its own
``defect`` steps, not the other sections') on fresh connections; any one
passes, and the case's detail names the reference's way when that is the one
that held. A server that keeps to the spec passes the reference profile too.

Every case says where it applies: ``profiles`` (``strict``, ``reference``) and
``dialects`` (``ros1``, ``ros2``) are required. Whatever a case leaves out has its
reason in ``skip``, a table keyed by the profile, the dialect or
``"profile+dialect"`` (``{ "reference+ros1" = "REF §1.3: ..." }``, which
also narrows a case that otherwise runs everywhere); the runner reports the
reason when it skips. Optional per case: ``transports`` (``ws``/``tcp``/``webrtc``),
``pending`` (a reason: skipped until the feature exists), ``authenticates =
true`` (the case sends ``auth`` itself: it needs the server's secret, and the
runner does not authenticate its connections first).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path
from typing import Any

from rwt_protocol.errors import RwtError

from .versions import SpecVersion, VersionRange

__all__ = [
    "Case",
    "Dialect",
    "Profile",
    "Requirement",
    "Step",
    "StepKind",
    "Suite",
    "SuiteError",
    "default_suite_dir",
    "load_suite",
]


class Profile(StrEnum):
    """What a run holds the server to.

    ``strict`` requires rwt's docs/decisions.md; ``reference`` accepts what
    rosbridge_suite does where those decisions depart from it (silence
    instead of ``status``, and so on).
    """

    STRICT = "strict"
    REFERENCE = "reference"


class Dialect(StrEnum):
    """The ROS edition a server speaks (how times, type names and rosapi fields look).

    ``ros1``: ``secs``/``nsecs``, ``pkg/Type``, rosbridge_suite 0.11.x;
    ``ros2``: ``sec``/``nanosec``, ``pkg/msg/Type``, rosbridge_suite 2.x
    (docs/reference-behaviour.md REF §4.3, §4.6).
    """

    ROS1 = "ros1"
    ROS2 = "ros2"


class StepKind(StrEnum):
    """The action of one step (module docstring)."""

    SEND = "send"
    SEND_RAW = "send_raw"
    SEND_BINARY = "send_binary"
    SEND_AUTH = "send_auth"
    EXPECT = "expect"
    EXPECT_STATUS = "expect_status"
    EXPECT_NONE = "expect_none"
    EXPECT_CLOSED = "expect_closed"
    SYNC = "sync"
    OPEN = "open"
    CLOSE = "close"


_STEP_OPTIONS = {
    "on",
    "profile",
    "dialect",
    "not_in",
    "timeout_s",
    "count",
    "binary",
    "repeat",
    "pace_s",
    "in_order",
    "defect",
    "unless_defect",
}
_CASE_KEYS = {
    "id",
    "title",
    "requirements",
    "steps",
    "profiles",
    "dialects",
    "skip",
    "transports",
    "pending",
    "authenticates",
}
TRANSPORTS = ("ws", "tcp", "webrtc")


class SuiteError(RwtError):
    """The suite's data is malformed; the text names the file and the case."""


@dataclass(frozen=True, slots=True)
class Requirement:
    """One rule the suite checks.

    Attributes:
        id: stable identifier (``spec.publish.unknown-topic``, ``D11``...).
        source: where the rule comes from (``spec 3.3.3``, ``docs/decisions.md
            D11``, ``REF §8.1 W1``).
        statement: the rule in one sentence.
        versions: the spec versions it holds for (``since``/``until``; default:
            every version, ``versions``).
    """

    id: str
    source: str
    statement: str
    versions: VersionRange = field(default_factory=VersionRange)


@dataclass(frozen=True, slots=True)
class Step:
    """One step of a case transcript.

    Attributes:
        kind: the action.
        on: the connection it acts on.
        value: the frame, pattern or raw text (None for sync/open/close).
        count: how many matching frames an ``expect`` needs.
        binary: an ``expect`` that requires CBOR frames (True) or JSON text
            frames (False); None takes either.
        profile: run only in this profile, or in both when None.
        dialect: run only against a server of this dialect, or both when None.
        not_in: ``skip`` keys (profile, dialect, ``profile+dialect``) where the
            step is left out.
        timeout_s: seconds this step may wait, or None for the run's default.
        repeat: how many times the step runs (``${i}`` = 0, 1, ...).
        pace_s: seconds between two repetitions (0: back to back).
        in_order: the expected frame must be the first one received with the
            pattern's ``op`` and ``topic``.
        defect: the docs/reference-behaviour.md section of a reference defect this
            step expects (module docstring), or None.
        unless_defect: a step of the spec's way, left out of the reference's.
    """

    kind: StepKind
    on: str = "a"
    value: object = None
    count: int = 1
    binary: bool | None = None
    profile: Profile | None = None
    dialect: Dialect | None = None
    not_in: frozenset[str] = frozenset()
    timeout_s: float | None = None
    repeat: int = 1
    pace_s: float = 0.0
    in_order: bool = False
    defect: str | None = None
    unless_defect: bool = False

    def runs_in(self, profile: Profile, dialect: Dialect) -> bool:
        """Whether the step runs in ``profile`` against a ``dialect`` server.

        ``expect_status`` steps run in ``strict`` only: rosbridge_suite never
        sends status (docs/reference-behaviour.md REF §2.21).
        """
        if self.profile is not None and self.profile is not profile:
            return False
        if self.dialect is not None and self.dialect is not dialect:
            return False
        if self.kind is StepKind.EXPECT_STATUS and profile is Profile.REFERENCE:
            return False
        where = {profile.value, dialect.value, f"{profile.value}+{dialect.value}"}
        return not self.not_in & where


@dataclass(frozen=True, slots=True)
class Case:
    """A transcript checking one or more requirements.

    ``skip`` maps what the case leaves out (a profile, a dialect, or
    ``"profile+dialect"``) to the reason shown when it is skipped there.
    ``versions`` are the ranges of its requirements (set by ``load_suite``): the
    case runs for a spec version one of them holds for.
    """

    id: str
    title: str
    requirements: tuple[str, ...]
    steps: tuple[Step, ...]
    profiles: frozenset[Profile] = frozenset(Profile)
    dialects: frozenset[Dialect] = frozenset(Dialect)
    skip: dict[str, str] = field(default_factory=dict)
    transports: frozenset[str] = frozenset(TRANSPORTS)
    pending: str | None = None
    authenticates: bool = False
    file: str = ""
    versions: tuple[VersionRange, ...] = ()

    def version_skip(self, version: SpecVersion) -> str | None:
        """Why the case does not run for a server judged by ``version``, or None.

        It runs when any of its requirements holds for ``version``.
        """
        if not self.versions or any(r.holds(version) for r in self.versions):
            return None
        ranges = "; ".join(dict.fromkeys(str(r) for r in self.versions))
        return f"holds for {ranges}; the server is judged by {version.label}"

    def defects(self, profile: Profile, dialect: Dialect) -> tuple[str, ...]:
        """The reference defects this case accepts in ``profile`` against ``dialect``.

        Returns:
            The ``defect`` sections of its steps that run there, in order, once each.
        """
        found = [s.defect for s in self.steps if s.defect and s.runs_in(profile, dialect)]
        return tuple(dict.fromkeys(found))

    def skip_reason(self, profile: Profile, dialect: Dialect) -> str | None:
        """Why the case does not run in ``profile`` against a ``dialect`` server, or None."""
        if profile not in self.profiles:
            return self.skip.get(profile.value, f"not part of the {profile.value} profile")
        if dialect not in self.dialects:
            return self.skip.get(dialect.value, f"not for a {dialect.value} server")
        return self.skip.get(f"{profile.value}+{dialect.value}")


@dataclass(frozen=True, slots=True)
class Suite:
    """Requirements (in file order) and the cases that check them."""

    requirements: dict[str, Requirement]
    cases: tuple[Case, ...]
    directory: Path = field(default_factory=Path)

    def cases_for(self, requirement_id: str) -> list[Case]:
        """The cases naming ``requirement_id``."""
        return [case for case in self.cases if requirement_id in case.requirements]


def default_suite_dir() -> Path:
    """Where the shipped suite lives: this package's folder.

    ``requirements.toml`` and ``cases/*.toml`` are package data, so a source
    checkout and an installed wheel find them in the same place.
    """
    return Path(__file__).parent


def load_suite(directory: Path | None = None) -> Suite:
    """Load ``requirements.toml`` and every ``cases/*.toml`` of a suite folder.

    Raises:
        SuiteError: a file is not valid TOML, a key is unknown, an id repeats, or
            a case names a requirement that does not exist.
    """
    directory = directory or default_suite_dir()
    requirements = _load_requirements(directory / "requirements.toml")
    cases: list[Case] = []
    for path in sorted((directory / "cases").glob("*.toml")):
        for table in _read(path).get("case", []):
            cases.append(_case(table, path.name))
    seen: set[str] = set()
    for case in cases:
        if case.id in seen:
            raise SuiteError(f"{case.file}: case id {case.id!r} repeats")
        seen.add(case.id)
        unknown = [r for r in case.requirements if r not in requirements]
        if unknown:
            raise SuiteError(f"{case.file}: case {case.id!r} names unknown requirements {unknown}")
    cases = [
        replace(c, versions=tuple(requirements[r].versions for r in c.requirements)) for c in cases
    ]
    return Suite(requirements, tuple(cases), directory)


def _read(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as file:
            return tomllib.load(file)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise SuiteError(f"{path.name}: {exc}") from None


def _load_requirements(path: Path) -> dict[str, Requirement]:
    requirements: dict[str, Requirement] = {}
    for table in _read(path).get("requirement", []):
        try:
            requirement = Requirement(
                id=str(table["id"]),
                source=str(table["source"]),
                statement=str(table["statement"]),
                versions=_versions(table),
            )
        except KeyError as exc:
            raise SuiteError(f"{path.name}: requirement {table} lacks {exc}") from None
        except ValueError as exc:
            raise SuiteError(f"{path.name}: requirement {table.get('id')!r}: {exc}") from None
        if requirement.id in requirements:
            raise SuiteError(f"{path.name}: requirement id {requirement.id!r} repeats")
        requirements[requirement.id] = requirement
    return requirements


def _versions(table: dict[str, Any]) -> VersionRange:
    """A requirement's ``since``/``until`` (``X.Y[.Z]`` or ``unversioned``; default: open)."""
    unknown = set(table) - {"id", "source", "statement", "since", "until"}
    if unknown:
        raise ValueError(f"unknown keys {sorted(unknown)}")
    since, until = table.get("since"), table.get("until")
    found = VersionRange(
        None if since is None else SpecVersion.parse(str(since)),
        None if until is None else SpecVersion.parse(str(until)),
    )
    if found.since is not None and found.until is not None and found.until <= found.since:
        raise ValueError(f"until ({found.until}) must come after since ({found.since})")
    return found


def _case(table: dict[str, object], file: str) -> Case:
    case_id = str(table.get("id", "?"))
    where = f"{file}: case {case_id!r}"
    unknown = set(table) - _CASE_KEYS
    if unknown or not {"id", "requirements", "profiles", "dialects"} <= set(table):
        raise SuiteError(
            f"{where}: needs id, requirements, profiles and dialects;"
            f" unknown keys {sorted(unknown)}"
        )
    steps = table.get("steps", [])
    if not isinstance(steps, list):
        raise SuiteError(f"{where}: steps must be an array")
    try:
        profiles = frozenset(Profile(p) for p in _strings(table["profiles"]))
        dialects = frozenset(Dialect(d) for d in _strings(table["dialects"]))
        skip = _skip_table(table.get("skip", {}))
        transports = frozenset(_strings(table.get("transports", list(TRANSPORTS))))
    except ValueError as exc:
        raise SuiteError(f"{where}: {exc}") from None
    if not transports <= set(TRANSPORTS):
        raise SuiteError(f"{where}: transports must be among {TRANSPORTS}")
    pending = table.get("pending")
    return Case(
        id=case_id,
        title=str(table.get("title", case_id)),
        requirements=tuple(_strings(table["requirements"])),
        steps=tuple(_step(step, f"{where} step {index + 1}") for index, step in enumerate(steps)),
        profiles=profiles,
        dialects=dialects,
        skip=skip,
        transports=transports,
        pending=None if pending is None else str(pending),
        authenticates=bool(table.get("authenticates", False)),
        file=file,
    )


def _step(table: object, where: str) -> Step:
    if not isinstance(table, dict):
        raise SuiteError(f"{where}: a step is a table")
    actions = [key for key in table if key not in _STEP_OPTIONS]
    if len(actions) != 1:
        raise SuiteError(f"{where}: expected one action key, got {sorted(actions)}")
    try:
        kind = StepKind(actions[0])
        profile = table.get("profile")
        dialect = table.get("dialect")
        if kind is StepKind.SEND_AUTH:
            _check_auth_fields(table[actions[0]])
        return Step(
            kind=kind,
            on=str(table.get("on", "a")),
            value=None if kind in _FLAGS else table[actions[0]],
            count=int(table.get("count", 1)),
            binary=None if "binary" not in table else bool(table["binary"]),
            profile=None if profile is None else Profile(profile),
            dialect=None if dialect is None else Dialect(dialect),
            not_in=_not_in(table.get("not_in", [])),
            timeout_s=None if "timeout_s" not in table else float(table["timeout_s"]),
            repeat=int(table.get("repeat", 1)),
            pace_s=float(table.get("pace_s", 0.0)),
            defect=None if "defect" not in table else str(table["defect"]),
            unless_defect=bool(table.get("unless_defect", False)),
            in_order=bool(table.get("in_order", False)),
        )
    except ValueError as exc:
        raise SuiteError(f"{where}: {exc}") from None


SKIP_KEYS = frozenset(
    [*(p.value for p in Profile), *(d.value for d in Dialect)]
    + [f"{p.value}+{d.value}" for p in Profile for d in Dialect]
)
"""What a case's ``skip`` table may be keyed by."""


def _skip_table(value: object) -> dict[str, str]:
    if not isinstance(value, dict) or not set(value) <= SKIP_KEYS:
        raise ValueError(f"skip takes a table with keys among {sorted(SKIP_KEYS)}")
    return {str(key): str(reason) for key, reason in value.items()}


def _not_in(value: object) -> frozenset[str]:
    keys = frozenset(_strings(value))
    if not keys <= SKIP_KEYS:
        raise ValueError(f"not_in takes keys among {sorted(SKIP_KEYS)}")
    return keys


AUTH_FIELDS = frozenset({"mac", "client", "dest", "rand", "level", "t_offset_s", "end_offset_s"})
"""What a ``send_auth`` table may set (the rest is made from the secret and the clock)."""


def _check_auth_fields(value: object) -> None:
    if not isinstance(value, dict) or not set(value) <= AUTH_FIELDS:
        raise ValueError(f"send_auth takes a table with keys among {sorted(AUTH_FIELDS)}")


_FLAGS = {StepKind.SYNC, StepKind.OPEN, StepKind.CLOSE, StepKind.EXPECT_CLOSED}


def _strings(value: object) -> list[str]:
    if isinstance(value, str):
        return [value]
    if isinstance(value, list):
        return [str(item) for item in value]
    raise ValueError(f"expected a string or an array of strings, got {value!r}")
