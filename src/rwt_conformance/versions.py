"""Versions of the rosbridge specification, and the ranges a requirement holds for.

The spec was one unversioned text ("rosbridge v2.0") up to rosbridge_suite
2.5.0/3.1.0/4.0.0; from 2.6.0/3.2.0/4.1.0 it is numbered under semantic
versioning: 2.0.0 (a ``publish`` with ``type`` advertises its topic), then 2.1.0
(2.7.0/3.3.0/4.2.0: an optional ``qos``), docs/reference-behaviour.md §13.2.

The unversioned text is spelled ``unversioned`` and orders before every
numbered version (``SpecVersion.UNVERSIONED < SpecVersion.parse("1.0")``). A
requirement's range (``since``, ``until`` in ``requirements.toml``) holds for
``since <= version < until``; a bound left out is open.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

__all__ = ["UNVERSIONED", "SpecVersion", "VersionRange"]

UNVERSIONED = "unversioned"
"""How the spec before 2.0.0 is spelled (``--spec-version``, ``since``/``until``, reports)."""


@dataclass(frozen=True, order=True, slots=True)
class SpecVersion:
    """A version of the spec: ``numbers`` (major, minor, patch), or the unversioned text.

    Attributes:
        rank: 0 for the unversioned text, 1 for a numbered version (orders it first).
        numbers: (major, minor, patch); (0, 0, 0) for the unversioned text.
    """

    rank: int
    numbers: tuple[int, int, int] = (0, 0, 0)

    UNVERSIONED: ClassVar[SpecVersion]

    @classmethod
    def of(cls, major: int, minor: int = 0, patch: int = 0) -> SpecVersion:
        """The numbered version ``major.minor.patch``."""
        return cls(1, (major, minor, patch))

    @classmethod
    def parse(cls, text: str) -> SpecVersion:
        """``unversioned``, ``X.Y`` or ``X.Y.Z`` (numbers of at most 4 digits).

        Raises:
            ValueError: anything else, saying what is taken.
        """
        text = text.strip()
        if text.lower() == UNVERSIONED:
            return cls.UNVERSIONED
        parts = text.split(".")
        if len(parts) in (2, 3) and all(p.isascii() and p.isdigit() and len(p) <= 4 for p in parts):
            major, minor, *patch = (int(p) for p in parts)
            return cls.of(major, minor, patch[0] if patch else 0)
        raise ValueError(f"not a spec version: {text!r} (X.Y, X.Y.Z or {UNVERSIONED!r})")

    @property
    def unversioned(self) -> bool:
        """Whether this is the unversioned text (before 2.0.0)."""
        return self.rank == 0

    @property
    def label(self) -> str:
        """``spec 2.1.0`` or ``the unversioned spec``, for sentences."""
        return f"the {UNVERSIONED} spec" if self.unversioned else f"spec {self}"

    def __str__(self) -> str:
        return UNVERSIONED if self.unversioned else ".".join(str(n) for n in self.numbers)


SpecVersion.UNVERSIONED = SpecVersion(0)


@dataclass(frozen=True, slots=True)
class VersionRange:
    """The spec versions a requirement holds for: ``since <= v < until`` (None: open).

    The default range holds for every version.
    """

    since: SpecVersion | None = None
    until: SpecVersion | None = None

    def holds(self, version: SpecVersion) -> bool:
        """Whether the requirement holds for a server judged by ``version``."""
        if self.since is not None and version < self.since:
            return False
        return self.until is None or version < self.until

    @property
    def everywhere(self) -> bool:
        """Whether the range is open at both ends (every version)."""
        return self.since is None and self.until is None

    def __str__(self) -> str:
        """``spec 2.0.0 and later``, ``the unversioned spec (before 2.0.0)``..."""
        since, until = self.since, self.until
        if since is None and until is None:
            return "every spec version"
        if since is None:
            assert until is not None
            if until == SpecVersion.of(2):
                return f"the {UNVERSIONED} spec (before 2.0.0)"
            return f"spec versions before {until}"
        if until is None:
            return f"{since.label} and later"
        return f"{since.label} up to, not including, {until}"
