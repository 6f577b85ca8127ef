"""Message, service and action types as the rest of the server sees them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from rwt_protocol.errors import FieldError
from rwt_protocol.shortcuts import enabled

from .convert import Context, ConvertFn, DefaultFn, compile_message, is_header, is_time_type
from .fastpath import FastFn, compile_fast
from .interop import from_rosbags, to_rosbags
from .names import Dialect
from .rosbagsfast import FromFn, ToFn, compile_from_rosbags, compile_to_rosbags

if TYPE_CHECKING:
    from collections.abc import Callable

    from rosbags.typesys.store import Typestore

    from .spec import Constant, FieldSpec

__all__ = ["ActionType", "Converted", "MessageType", "ServiceType"]

_RULE = "=" * 80


def _no_fast(value: object) -> None:
    """The fast converter of a type that has none: every value takes the general path."""
    return None


class Converted(NamedTuple):
    """The result of converting a JSON value to a message.

    A named tuple: one is built per published message, and a tuple is the
    cheapest immutable record to build (B14).

    Attributes:
        msg: the message in the internal form (a dict with every field).
        missing: JSON paths of the fields the input omitted and that were filled
            with defaults, for the warning of D7. An omitted
            nested message is one path, not one per field inside it.
    """

    msg: dict[str, object]
    missing: tuple[str, ...]


class MessageType:
    """One message type: its fields, constants, text and compiled converter.

    Build instances through :class:`TypeRegistry`; they are cached there.

    Attributes:
        name: canonical name, ``std_msgs/msg/String`` (ROS 2) or ``std_msgs/String`` (ROS 1).
        fields: the fields in declaration order.
        constants: the constants in declaration order.
        has_header: whether this type is, or has at any depth (arrays included),
            a ``std_msgs/Header``.
        rosbags_name: the name of this type in a rosbags typestore (``pkg/msg/Type``,
            ``pkg/srv/Type_Request``...).
    """

    def __init__(
        self,
        name: str,
        fields: tuple[FieldSpec, ...],
        constants: tuple[Constant, ...],
        text: str,
        *,
        dialect: Dialect,
        rosbags_name: str,
        resolve: Callable[[str], MessageType],
    ) -> None:
        self.name = name
        self.fields = fields
        self.constants = constants
        self.dialect = dialect
        self.rosbags_name = rosbags_name
        self._text = text.rstrip("\n")
        self._source = text  # verbatim: ROS 1's full text keeps each file's last newline
        self._resolve = resolve
        self._compiled: tuple[ConvertFn, DefaultFn] | None = None
        self._convert: ConvertFn | None = None
        #: ``fast(value)``: the internal form of a complete, well-typed value, else
        #: None (see ``fastpath``); compiled on the first call. With the shortcut
        #: off (``RWT_NO_SHORTCUTS``) always None: every value takes the general path.
        self.fast: FastFn = self._first_fast if enabled("generated-converters") else _no_fast
        self._has_header: bool | None = None
        #: generated rosbags converters (``rosbagsfast``), unless that shortcut is off
        self._rosbags_fast = enabled("rosbags-converters")
        self._to_rosbags: tuple[Typestore, ToFn] | None = None
        self._from_rosbags: FromFn | None = None

    def __repr__(self) -> str:
        return f"MessageType({self.name!r})"

    def compiled(self) -> tuple[ConvertFn, DefaultFn]:
        """The compiled ``(convert, default)`` pair (built on first use, then cached)."""
        if self._compiled is None:
            self._compiled = compile_message(self.name, self.fields, self.dialect, self._lookup)
        return self._compiled

    def _lookup(self, name: str) -> tuple[ConvertFn, DefaultFn]:
        return self._resolve(name).compiled()

    def fast_converter(self) -> FastFn | None:
        """The generated converter of complete, well-typed values (``fastpath``), or None."""
        fast = self._compiled_fast()
        return None if fast is _no_fast else fast

    def _first_fast(self, value: object) -> dict[str, object] | None:
        return self._compiled_fast()(value)

    def _compiled_fast(self) -> FastFn:
        if self.fast == self._first_fast:  # not compiled yet
            self.fast = self._compile_fast()
        return self.fast

    def _compile_fast(self) -> FastFn:
        found = compile_fast(
            self.name, self.fields, self.dialect, lambda name: self._resolve(name).fast_converter()
        )
        return _no_fast if found is None else found

    @property
    def has_header(self) -> bool:
        """Whether a ``std_msgs/Header`` occurs anywhere in this type (D8)."""
        if self._has_header is None:
            self._has_header = is_header(self.name) or any(
                is_header(name) for name in self.dependency_names()
            )
        return self._has_header

    def from_json(self, value: object, *, path: str = "$", now: float) -> Converted:
        """Convert a JSON-decoded value to the internal form.

        Args:
            value: the decoded JSON (dicts, lists, str, int, float, bool, None).
            path: JSON path of ``value``, used in error texts (``$.msg``).
            now: wall-clock seconds since the epoch, used for ``"now"`` and for
                header stamps that are omitted (D8).

        Returns:
            The message and the paths of omitted fields (D7).

        Raises:
            FieldError: a value does not fit its field (D9, D10), a key is not a
                field, or ``value`` is not an object; the error names the path.
        """
        fast_msg = self.fast(value)
        if fast_msg is not None:
            return Converted(fast_msg, ())
        convert = self._convert
        if convert is None:
            convert = self._convert = self.compiled()[0]
        ctx = Context(now)
        msg = convert(value, path, ctx)
        missing = ctx.missing
        return Converted(msg, tuple(missing) if missing else ())  # type: ignore[arg-type]

    def default(self, *, now: float | None = None) -> dict[str, object]:
        """Build the default value: written defaults, else zeros, empty arrays.

        Args:
            now: when given, header stamps are this time (seconds since the
                epoch, D8); otherwise they are zero.
        """
        return self.compiled()[1](now)  # type: ignore[return-value]

    def from_python(self, obj: object, *, now: float | None = None) -> dict[str, object]:
        """Convert a dict (checked like JSON) or a rosbags message object.

        Args:
            obj: a JSON-like dict, or a rosbags message of this type (a dataclass
                whose arrays may be numpy arrays; its values are checked too).
            now: seconds since the epoch for omitted header stamps; zero when None.

        Returns:
            The message in the internal form.

        Raises:
            FieldError: a value does not fit its field, or ``obj`` is a rosbags
                message of another type.
        """
        msgtype = getattr(obj, "__msgtype__", None)
        if isinstance(msgtype, str) and not isinstance(obj, dict):
            if msgtype != self.rosbags_name:
                raise FieldError("$", f"expected object (type {self.name}), got {msgtype}")
            obj = self.plain_from_rosbags(obj)
        return self.from_json(obj, now=0.0 if now is None else now).msg

    def to_rosbags(self, msg: dict[str, object], typestore: Typestore) -> object:
        """Build the rosbags object of ``msg`` (internal form) for serialization.

        Args:
            msg: a message of this type in the internal form.
            typestore: a store holding this type, see ``TypeRegistry.typestore()``.

        Raises:
            KeyError: the store lacks this type or ``msg`` lacks a field.
        """
        return self.to_rosbags_converter(typestore)(msg)

    def to_rosbags_converter(self, typestore: Typestore) -> ToFn:
        """The function ``msg -> rosbags object`` of ``to_rosbags`` for ``typestore`` (cached).

        Generated once per type (``rosbagsfast``); the general walk of
        ``interop.to_rosbags`` when the ``rosbags-converters`` shortcut is off.

        Raises:
            KeyError: the store lacks this type or a nested one.
        """
        cached = self._to_rosbags
        if cached is not None and cached[0] is typestore:
            return cached[1]
        if self._rosbags_fast:
            found = compile_to_rosbags(
                self,
                typestore,
                lambda name: self._resolve(name).to_rosbags_converter(typestore),
                self._resolve,
            )
        else:

            def found(msg: dict[str, object]) -> object:
                return to_rosbags(msg, self, typestore, self._resolve)

        self._to_rosbags = (typestore, found)
        return found

    def plain_from_rosbags(self, obj: object) -> dict[str, object]:
        """A rosbags message object of this type as JSON-like values, unchecked.

        The result still goes through ``fast`` or ``from_json`` to become the
        internal form (its numeric arrays are lists, its times ``sec``/``nanosec``).
        """
        return self.from_rosbags_converter()(obj)

    def from_rosbags_converter(self) -> FromFn:
        """The function of ``plain_from_rosbags`` (generated on first use, then cached)."""
        if self._from_rosbags is None:
            if self._rosbags_fast:
                self._from_rosbags = compile_from_rosbags(
                    self, lambda name: self._resolve(name).from_rosbags_converter(), self._resolve
                )
            else:
                self._from_rosbags = lambda obj: from_rosbags(obj, self, self._resolve)
        return self._from_rosbags

    def definition_text(self) -> str:
        """The definition text of this type alone, ending in a newline (empty if no lines)."""
        return f"{self._text}\n" if self._text else ""

    def dependency_names(self) -> list[str]:
        """Canonical names of the message types used by this one, depth first, each once.

        Times are not listed in ROS 1, where they are primitives.
        """
        seen: list[str] = []
        self._collect(seen)
        return seen

    def _collect(self, seen: list[str]) -> None:
        for spec in self.fields:
            if spec.type.is_message and spec.type.base not in seen:
                seen.append(spec.type.base)
                if not is_time_type(spec.type):
                    self._resolve(spec.type.base)._collect(seen)

    def full_text(self) -> str:
        """The definition with its dependencies, in the ``gendeps --cat`` layout.

        This type's text, then for each dependency a line of 80 ``=``, a line
        ``MSG: pkg/Type`` and that type's text (REF §3.5, §7.1 L59).
        """
        if self.dialect is Dialect.ROS1:
            return self._genmsg_full_text()
        parts = [self.definition_text()]
        for name in self.dependency_names():
            dep = self._resolve(name)
            package, _, short = name.partition("/")
            short = short.rpartition("/")[2]
            parts.append(f"{_RULE}\nMSG: {package}/{short}\n{dep.definition_text()}")
        return "".join(parts)

    def _genmsg_full_text(self) -> str:
        """ROS 1's full text byte for byte as genmsg's ``compute_full_text`` joins it.

        Each file's text as written, a newline after each, the last one cut: what
        a ROS 1 publisher sends as ``message_definition`` and what ``rosbag
        check`` compares with the installed types (``migration.py``, ``find_path``).
        """
        parts = [self._source, "\n"]
        for name in self.dependency_names():
            package, _, short = name.partition("/")
            short = short.rpartition("/")[2]
            parts += [f"{_RULE}\nMSG: {package}/{short}\n", self._resolve(name)._source, "\n"]
        return "".join(parts)[:-1]


@dataclass(frozen=True, slots=True)
class ServiceType:
    """A service type: its request and response messages.

    Attributes:
        name: canonical name, ``std_srvs/srv/Empty`` (ROS 2) or ``std_srvs/Empty`` (ROS 1).
        request: the request message type.
        response: the response message type.
        text: the whole ``.srv`` text.
    """

    name: str
    request: MessageType
    response: MessageType
    text: str


@dataclass(frozen=True, slots=True)
class ActionType:
    """An action type: its goal, result and feedback messages (ROS 2 layout).

    Attributes:
        name: canonical name, ``example_interfaces/action/Fibonacci``.
        goal: the goal message type.
        result: the result message type.
        feedback: the feedback message type.
        text: the whole ``.action`` text.
    """

    name: str
    goal: MessageType
    result: MessageType
    feedback: MessageType
    text: str
