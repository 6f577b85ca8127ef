"""A parser of ``.msg``, ``.srv`` and ``.action`` text.

rosbags' field definitions drop the default values written in a definition, and
D7 needs them, so rwt reads interface text itself. Grammar
(ROS 2 with the ROS 1 forms): one declaration per line, ``TYPE NAME [DEFAULT]``
or ``TYPE NAME=VALUE`` for a constant; ``#`` starts a comment; types may be
bounded strings (``string<=N``) and arrays (``[N]``, ``[<=N]``, ``[]``); a line
``---`` separates the parts of a service (2) or an action (3).
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass

from rwt_protocol.errors import GraphError

from .names import Dialect, InvalidTypeNameError, parse_type_name
from .primitives import Problem, array_checker, scalar_checker
from .spec import PRIMITIVES, ArrayKind, Constant, FieldSpec, FieldType

__all__ = [
    "DefinitionError",
    "ParsedMessage",
    "parse_message",
    "resolve_base",
    "split_sections",
]

_DECLARATION = re.compile(
    r"(?P<type>[A-Za-z][^\s#]*)\s+"
    r"(?P<name>[A-Za-z][A-Za-z0-9_]*)\s*(?P<rest>.*)\Z"
)
_TYPE = re.compile(
    r"(?P<base>[A-Za-z][A-Za-z0-9_/]*)(?:<=(?P<sbound>\d+))?"
    r"(?:\[(?P<bounded><=)?(?P<size>\d*)\])?\Z"
)
_TIME_TYPES = {"time": "Time", "duration": "Duration"}


class DefinitionError(GraphError):
    """An interface definition cannot be parsed.

    Args:
        origin: where the text came from (a file path or a type name).
        line: 1-based line number, 0 for the whole text.
        problem: what is wrong.
    """

    def __init__(self, origin: str, line: int, problem: str) -> None:
        super().__init__(f"{origin}:{line}: {problem}")
        self.origin = origin
        self.line = line
        self.problem = problem


@dataclass(frozen=True, slots=True)
class ParsedMessage:
    """The fields, constants and own text of one message definition."""

    fields: tuple[FieldSpec, ...]
    constants: tuple[Constant, ...]
    text: str


def split_sections(text: str, count: int, origin: str) -> list[str]:
    """Split a ``.srv`` (count 2) or ``.action`` (count 3) text at its ``---`` lines.

    Raises:
        DefinitionError: the text has another number of parts.
    """
    sections: list[list[str]] = [[]]
    for line in text.splitlines():
        if line.strip() == "---":
            sections.append([])
        else:
            sections[-1].append(line)
    if len(sections) != count:
        raise DefinitionError(origin, 0, f"expected {count} parts separated by ---")
    return ["\n".join(lines) for lines in sections]


def resolve_base(token: str, package: str, dialect: Dialect) -> tuple[str, bool]:
    """Resolve the base type named inside package ``package``'s definitions.

    ``Header`` means ``std_msgs/Header``; a bare name means a type of ``package``;
    ``pkg/Type`` and ``pkg/msg/Type`` are both accepted. Times are primitives in
    ROS 1 and ``builtin_interfaces`` messages in ROS 2, whichever way they are
    spelled.

    Returns:
        ``(base, is_message)`` where a message base is its canonical name.

    Raises:
        InvalidTypeNameError: a slashed name is malformed.
    """
    if token in _TIME_TYPES:
        if dialect is Dialect.ROS1:
            return token, False
        return f"builtin_interfaces/msg/{_TIME_TYPES[token]}", True
    if token in PRIMITIVES:
        return token, False
    if "/" in token:
        name = parse_type_name(token)
    elif token == "Header":
        name = parse_type_name("std_msgs/Header")
    else:
        name = parse_type_name(f"{package}/{token}")
    if dialect is Dialect.ROS1 and name.package == "builtin_interfaces":
        lowered = name.type.lower()
        if lowered in _TIME_TYPES:
            return lowered, False
    return name.spelled(dialect), True


def _parse_type(token: str, package: str, dialect: Dialect) -> FieldType:
    match = _TYPE.match(token)
    if match is None:
        raise ValueError(f"malformed type {token!r}")
    try:
        base, is_message = resolve_base(match["base"], package, dialect)
    except InvalidTypeNameError:
        raise ValueError(f"malformed type {token!r}") from None
    string_bound = int(match["sbound"]) if match["sbound"] else None
    if string_bound is not None and base not in ("string", "wstring"):
        raise ValueError(f"only strings have a bound: {token!r}")
    if match["size"] is None:
        array, length = ArrayKind.NONE, None
    elif match["bounded"]:
        if not match["size"]:
            raise ValueError(f"bounded array without a bound: {token!r}")
        array, length = ArrayKind.BOUNDED, int(match["size"])
    elif match["size"]:
        array, length = ArrayKind.FIXED, int(match["size"])
    else:
        array, length = ArrayKind.UNBOUNDED, None
    return FieldType(base, is_message, array, length, string_bound)


def _unquote(text: str) -> tuple[str, bool]:
    """Strip one pair of quotes (and a comment after them); report if there were quotes."""
    if text[:1] in ("'", '"'):
        quote = text[0]
        end = 1
        while end < len(text) and text[end] != quote:
            end += 2 if text[end] == "\\" else 1
        inner = text[1:end]
        return inner.replace("\\" + quote, quote).replace("\\\\", "\\"), True
    return text, False


def _scalar_literal(text: str, base: str) -> object:
    if base == "bool":
        lowered = text.lower()
        if lowered in ("true", "1"):
            return True
        if lowered in ("false", "0"):
            return False
        raise ValueError(f"not a bool: {text!r}")
    if base in ("float32", "float64"):
        return float(text)
    if base in ("string", "wstring"):
        return _unquote(text.strip())[0]
    try:
        return int(text, 10)
    except ValueError:
        return int(text, 0)


def _array_literal(text: str, base: str) -> list[object]:
    body = text.strip()
    if not (body.startswith("[") and body.endswith("]")):
        raise ValueError(f"expected [a, b, ...], got {text!r}")
    if base in ("string", "wstring"):
        try:
            value = ast.literal_eval(body)
        except (ValueError, SyntaxError):
            return [part.strip() for part in body[1:-1].split(",") if part.strip()]
        if isinstance(value, list) and all(isinstance(v, str) for v in value):
            return value
        raise ValueError(f"expected an array of strings, got {text!r}")
    inner = body[1:-1].strip()
    if not inner:
        return []
    return [_scalar_literal(part.strip(), base) for part in inner.split(",")]


def _value_text(rest: str, base: str, keep_hash: bool) -> str:
    """The literal part of a default or constant, without a trailing comment."""
    stripped = rest.strip()
    if base in ("string", "wstring") and stripped[:1] in ("'", '"'):
        return stripped
    if keep_hash:
        return stripped
    return stripped.split("#", 1)[0].strip()


def _default(ftype: FieldType, text: str, dialect: Dialect) -> object:
    if ftype.is_message or ftype.base in _TIME_TYPES:
        raise ValueError("only primitive fields may have a default")
    try:
        if ftype.array is ArrayKind.NONE:
            check = scalar_checker(ftype.base, dialect, ftype.string_bound)
            return check(_scalar_literal(text, ftype.base))
        return array_checker(ftype, dialect)(_array_literal(text, ftype.base))
    except Problem as problem:
        raise ValueError(f"bad default {text!r}: {problem.problem}") from None
    except ValueError as error:
        raise ValueError(f"bad default {text!r}: {error}") from None


def _constant(ftype: FieldType, name: str, text: str, dialect: Dialect) -> Constant:
    if ftype.is_message or ftype.array is not ArrayKind.NONE or ftype.base in _TIME_TYPES:
        raise ValueError("constants must have a primitive, non-array type")
    if ftype.base in ("string", "wstring"):
        value: object = _unquote(text)[0]
    else:
        try:
            check = scalar_checker(ftype.base, dialect)
            value = check(_scalar_literal(text, ftype.base))
        except Problem as problem:
            raise ValueError(f"bad constant {text!r}: {problem.problem}") from None
    return Constant(name, ftype.base, value)


def _parse_line(line: str, package: str, dialect: Dialect) -> FieldSpec | Constant | None:
    stripped = line.strip()
    if not stripped or stripped.startswith("#"):
        return None
    match = _DECLARATION.match(stripped)
    if match is None:
        raise ValueError(f"expected 'TYPE NAME', got {stripped!r}")
    ftype = _parse_type(match["type"], package, dialect)
    rest = match["rest"]
    if rest.startswith("="):
        keep_hash = dialect is Dialect.ROS1 and ftype.base == "string"
        return _constant(
            ftype, match["name"], _value_text(rest[1:], ftype.base, keep_hash), dialect
        )
    value_text = _value_text(rest, ftype.base, keep_hash=False)
    if not value_text:
        return FieldSpec(match["name"], ftype)
    return FieldSpec(match["name"], ftype, _default(ftype, value_text, dialect))


def parse_message(
    text: str, *, package: str, dialect: Dialect, origin: str = "<text>"
) -> ParsedMessage:
    """Parse the text of one message (or one part of a service or action).

    Args:
        text: the definition text.
        package: the package the definition belongs to (resolves bare type names).
        dialect: decides ``time``, ``byte`` and the spelling of type names.
        origin: named in error texts.

    Returns:
        Fields in declaration order with their written defaults (internal form),
        constants, and the text itself.

    Raises:
        DefinitionError: a line cannot be parsed, a default or constant does not
            fit its type, or a name is declared twice.
    """
    fields: list[FieldSpec] = []
    constants: list[Constant] = []
    seen: set[str] = set()
    for number, line in enumerate(text.splitlines(), start=1):
        try:
            item = _parse_line(line, package, dialect)
        except ValueError as error:
            raise DefinitionError(origin, number, str(error)) from None
        if item is None:
            continue
        if item.name in seen:
            raise DefinitionError(origin, number, f"{item.name!r} declared twice")
        seen.add(item.name)
        (fields if isinstance(item, FieldSpec) else constants).append(item)  # type: ignore[arg-type]
    return ParsedMessage(tuple(fields), tuple(constants), text)
