"""Which topics a recording (or ``rwt bag filter``) takes, as ``ros2 bag record`` selects them.

Globs (``--topics``) and a regular expression (``-e/--regex``) include topics;
a topic matching either is taken (all when neither is given). ``--exclude-regex``
and ``--exclude-topics`` (exact names) then take topics out again. Expressions
are searched anywhere in the name (``re.search``), as rosbag2's ``std::regex_search``.
"""

from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .errors import BagError

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["TopicSelection", "compile_regex"]


def compile_regex(pattern: str | None, option: str) -> re.Pattern[str] | None:
    """``pattern`` compiled (None for None or empty).

    Raises:
        BagError: not a valid Python regular expression; the text names ``option``.
    """
    if not pattern:
        return None
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise BagError(f"{option} {pattern!r} is not a regular expression: {exc}") from exc


@dataclass(frozen=True)
class TopicSelection:
    """The topics to take.

    Attributes:
        globs: shell patterns of names to include (``/tf*``).
        regex: a regular expression of names to include.
        exclude_regex: a regular expression of names to leave out.
        exclude_topics: names to leave out.
    """

    globs: tuple[str, ...] = ()
    regex: re.Pattern[str] | None = None
    exclude_regex: re.Pattern[str] | None = None
    exclude_topics: frozenset[str] = field(default_factory=frozenset)

    @classmethod
    def of(
        cls,
        globs: Iterable[str] = (),
        *,
        regex: str | None = None,
        exclude_regex: str | None = None,
        exclude_topics: Iterable[str] = (),
        option_prefix: str = "",
    ) -> TopicSelection:
        """A selection from option values (expressions as text).

        ``option_prefix`` names the options in errors (``record-``: ``--record-regex``).

        Raises:
            BagError: an expression is not valid.
        """
        return cls(
            tuple(globs),
            compile_regex(regex, f"--{option_prefix}regex"),
            compile_regex(exclude_regex, f"--{option_prefix}exclude-regex"),
            frozenset(exclude_topics),
        )

    @property
    def patterns(self) -> tuple[str, ...]:
        """The include globs as given (``*`` when nothing includes: every topic)."""
        return self.globs or (() if self.regex else ("*",))

    def matches(self, topic: str) -> bool:
        """Whether ``topic`` is taken."""
        if topic in self.exclude_topics:
            return False
        if self.exclude_regex is not None and self.exclude_regex.search(topic):
            return False
        if self.regex is not None and self.regex.search(topic):
            return True
        return any(fnmatch.fnmatchcase(topic, pattern) for pattern in self.patterns)
