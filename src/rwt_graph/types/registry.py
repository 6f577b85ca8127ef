"""The type registry: resolves type strings to message, service and action types."""

from __future__ import annotations

from contextlib import suppress
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar, cast

from rosbags.typesys import Stores, get_typestore

from rwt_protocol.errors import GraphError

from .interop import WSTRING_DEFINITION, WSTRING_TYPE, fielddefs

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping, Sequence

    from rosbags.interfaces.typing import Typesdict
    from rosbags.typesys.store import Typestore
from .genaction import wrapper_of, wrapper_text
from .message import ActionType, MessageType, ServiceType
from .msgparse import DefinitionError, ParsedMessage, parse_message, split_sections
from .names import Dialect, Kind, TypeName, UnknownTypeError, parse_type_name
from .sources import FileIndex, packaged_dirs, store_dialects, store_message, stores_for
from .wire import WireCodec

__all__ = ["TypeRegistry", "codec_for"]

_PARTS: dict[str, tuple[str, ...]] = {
    "srv": ("Request", "Response"),
    "action": ("Goal", "Result", "Feedback"),
}
_ALIAS_LIMIT = 4096

T = TypeVar("T", ServiceType, ActionType)


class TypeRegistry:
    """Every message, service and action type the server knows, by name.

    Sources, highest precedence first: ``interface_dirs`` (each holding
    ``<pkg>/msg|srv|action/*``), the packaged ROS 1 overlay (ROS 1 only), the
    packaged interfaces, then the rosbags store of the dialect (messages only).
    Files are listed at construction and parsed on first use; types are cached.

    Args:
        dialect: ROS 2 (default) or ROS 1 (D6).
        interface_dirs: extra folders of interface files, highest precedence first.
    """

    def __init__(
        self, dialect: Dialect = Dialect.ROS2, interface_dirs: Sequence[Path] = ()
    ) -> None:
        self.dialect = Dialect(dialect)
        roots = [Path(folder) for folder in interface_dirs] + packaged_dirs(self.dialect)
        self._files = FileIndex(roots)
        self._stores = list(
            zip(store_dialects(self.dialect), stores_for(self.dialect), strict=True)
        )
        self._store_keys = [key for _, store in self._stores for key in store]
        self._packages = self._files.packages() | {k.split("/")[0] for k in self._store_keys}
        self._messages: dict[str, MessageType] = {}
        self._aliases: dict[str, MessageType] = {}
        self._services: dict[str, ServiceType] = {}
        self._actions: dict[str, ActionType] = {}
        self._typestore: Typestore | None = None
        self._resolving: set[str] = set()
        self._codecs: dict[str, WireCodec] = {}

    def canonical_name(self, name: str, kind: Kind = "msg") -> str:
        """Validate a type string and spell it canonically, without looking it up.

        Returns:
            ``pkg/<kind>/Type`` in ROS 2, ``pkg/Type`` in ROS 1 (D5).

        Raises:
            InvalidTypeNameError: the string is malformed (REF §4.6).
        """
        return parse_type_name(name, kind).spelled(self.dialect)

    def message(self, name: str) -> MessageType:
        """Find a message type by any accepted spelling (cached).

        ``pkg/srv/Type_Request`` and the other generated parts of services and
        actions are messages too.

        Raises:
            InvalidTypeNameError: the string is malformed (REF §4.6).
            UnknownTypeError: no such type, or a type it uses is unknown.
            DefinitionError: its definition (or a dependency's) cannot be parsed.
        """
        found = self._aliases.get(name)
        if found is not None:
            return found
        found = self._message(parse_type_name(name, "msg"))
        if len(self._aliases) < _ALIAS_LIMIT:
            self._aliases[name] = found
        return found

    def _message(self, tname: TypeName) -> MessageType:
        canonical = tname.spelled(self.dialect)
        found = self._messages.get(canonical)
        if found is not None:
            return found
        if tname.kind != "msg":
            return self._part(tname, tname.kind)
        path = self._files.find(tname.package, "msg", tname.type)
        key = f"{tname.package}/msg/{tname.type}"
        if path is not None:
            text = path.read_text(encoding="utf-8")
            parsed = parse_message(
                text, package=tname.package, dialect=self.dialect, origin=str(path)
            )
            mtype = self._make(canonical, key, parsed)
        else:
            stored = self._from_stores(key)
            if stored is None:
                return self._part_or_unknown(tname)
            mtype = self._make(canonical, key, stored)
        if canonical in self._resolving:
            raise DefinitionError(canonical, 0, "the type uses itself")
        self._resolving.add(canonical)
        try:
            mtype.dependency_names()  # resolves (and so checks) every type it uses
        finally:
            self._resolving.discard(canonical)
        self._messages[canonical] = mtype
        return mtype

    def _from_stores(self, key: str) -> ParsedMessage | None:
        for origin, store in self._stores:
            stored = store_message(store, key, self.dialect, origin)
            if stored is not None:
                return ParsedMessage(*stored)
        return None

    def _make(self, canonical: str, rosbags_name: str, parsed: ParsedMessage) -> MessageType:
        return MessageType(
            canonical,
            parsed.fields,
            parsed.constants,
            parsed.text,
            dialect=self.dialect,
            rosbags_name=rosbags_name,
            resolve=self.message,
        )

    def _part_or_unknown(self, tname: TypeName) -> MessageType:
        """ROS 1 names service and action parts ``pkg/TypeRequest``; try those.

        ROS 1 also knows the wrappers genaction makes of an ``.action`` file
        (``pkg/XActionGoal``...; :mod:`.genaction`).
        """
        wrapper = self._genaction(tname) if self.dialect is Dialect.ROS1 else None
        if wrapper is not None:
            return wrapper
        for kind in ("srv", "action"):
            try:
                return self._part(tname, kind)
            except UnknownTypeError:
                continue
        known = tname.package in self._packages
        raise UnknownTypeError(tname.spelled(self.dialect), "msg", package_known=known)

    def _part(self, tname: TypeName, kind: str) -> MessageType:
        for index, part in enumerate(_PARTS[kind]):
            for suffix in (f"_{part}", part):
                if tname.type.endswith(suffix) and len(tname.type) > len(suffix):
                    owner = f"{tname.package}/{kind}/{tname.type[: -len(suffix)]}"
                    if kind == "srv":
                        service = self.service(owner)
                        return (service.request, service.response)[index]
                    action = self.action(owner)
                    return (action.goal, action.result, action.feedback)[index]
        raise UnknownTypeError(tname.spelled(self.dialect), "msg", package_known=True)

    def _genaction(self, tname: TypeName) -> MessageType | None:
        """A genaction wrapper of a ROS 1 ``.action`` file, or None (no such file)."""
        split = wrapper_of(tname.type)
        if split is None or self._files.find(tname.package, "action", split[0]) is None:
            return None
        action, suffix = split
        self.action(f"{tname.package}/{action}")  # checks the file and caches its parts
        canonical = tname.spelled(self.dialect)
        text = wrapper_text(action, suffix)
        parsed = parse_message(
            text, package=tname.package, dialect=self.dialect, origin=f"genaction {canonical}"
        )
        mtype = self._make(canonical, f"{tname.package}/msg/{tname.type}", parsed)
        self._messages[canonical] = mtype
        mtype.dependency_names()
        return mtype

    def _parts(self, tname: TypeName, kind: Kind) -> tuple[str, list[MessageType]]:
        """Parse the file of a service or action into its text and parts."""
        canonical = tname.spelled(self.dialect)
        path = self._files.find(tname.package, kind, tname.type)
        if path is None:
            raise UnknownTypeError(canonical, kind, package_known=tname.package in self._packages)
        text = path.read_text(encoding="utf-8")
        parts = _PARTS[kind]
        sections = split_sections(text, len(parts), str(path))
        types: list[MessageType] = []
        for part, section in zip(parts, sections, strict=True):
            origin = f"{path} ({part.lower()})"
            parsed = parse_message(
                section, package=tname.package, dialect=self.dialect, origin=origin
            )
            ros1 = self.dialect is Dialect.ROS1
            part_name = f"{canonical}{part}" if ros1 else f"{canonical}_{part}"
            rosbags_name = f"{tname.package}/{kind}/{tname.type}_{part}"
            types.append(self._make(part_name, rosbags_name, parsed))
        for mtype in types:
            mtype.dependency_names()
        for mtype in types:
            self._messages[mtype.name] = mtype
        return text, types

    def service(self, name: str) -> ServiceType:
        """Find a service type (cached).

        Raises:
            InvalidTypeNameError: the string is malformed (REF §4.6).
            UnknownTypeError: no ``.srv`` file defines it, or a type it uses is unknown.
            DefinitionError: its text cannot be parsed.
        """

        def build(canonical: str, tname: TypeName) -> ServiceType:
            text, (request, response) = self._parts(tname, "srv")
            return ServiceType(canonical, request, response, text)

        return self._lookup(self._services, name, "srv", build)

    def action(self, name: str) -> ActionType:
        """Find an action type (cached).

        Raises:
            InvalidTypeNameError: the string is malformed (REF §4.6).
            UnknownTypeError: no ``.action`` file defines it, or a type it uses is unknown.
            DefinitionError: its text cannot be parsed.
        """

        def build(canonical: str, tname: TypeName) -> ActionType:
            text, (goal, result, feedback) = self._parts(tname, "action")
            return ActionType(canonical, goal, result, feedback, text)

        return self._lookup(self._actions, name, "action", build)

    def _lookup(
        self,
        cache: dict[str, T],
        name: str,
        kind: Kind,
        build: Callable[[str, TypeName], T],
    ) -> T:
        # Cached by canonical name, and by each spelling asked for (bounded, as
        # the spellings come from peers).
        found = cache.get(name)
        if found is None:
            tname = parse_type_name(name, kind)
            canonical = tname.spelled(self.dialect)
            found = cache.get(canonical)
            if found is None:
                found = cache[canonical] = build(canonical, tname)
            if len(cache) < _ALIAS_LIMIT:
                cache[name] = found
        return found

    def message_names(self) -> list[str]:
        """Canonical names of every message type (files and store), sorted."""
        names = {TypeName(pkg, "msg", t) for pkg, t in self._files.names("msg")}
        for key in self._store_keys:
            package, _, short = key.partition("/msg/")
            names.add(TypeName(package, "msg", short))
        return sorted(name.spelled(self.dialect) for name in names)

    def service_names(self) -> list[str]:
        """Canonical names of every service type, sorted."""
        return sorted(
            TypeName(p, "srv", t).spelled(self.dialect) for p, t in self._files.names("srv")
        )

    def action_names(self) -> list[str]:
        """Canonical names of every action type, sorted."""
        return sorted(
            TypeName(p, "action", t).spelled(self.dialect) for p, t in self._files.names("action")
        )

    def serialize(self, mtype: MessageType, msg: Mapping[str, object]) -> bytes:
        """``msg`` (the internal form, as ``MessageType.from_json`` gives) in its wire form.

        The dialect's serialization: CDR for ROS 2, the ROS 1 format for ROS 1,
        as rosbags writes it (what a bag stores and rmw_zenoh carries).

        Raises:
            KeyError: the typestore lacks the type (a definition that failed to load).
        """
        return bytes(codec_for(self, mtype).serialize(msg))

    def typestore(self) -> Typestore:
        """A rosbags typestore with every known message type, for serialization.

        It starts from the dialect's stores (ROS 2 Jazzy; ROS 1 Noetic over
        Jazzy, see ``stores_for``) and adds or replaces every message defined
        by files, the request, response, goal, result and feedback parts of
        every service and action, all under their ``rosbags_name``. A file type that fails to load
        (unknown dependency, bad text) is left out; asking for it
        by name raises. Built once for a set of definitions, and shared by the
        registries with the same ones (the last few sets); treat it as read-only.
        """
        if self._typestore is None:
            own = {t.rosbags_name: fielddefs(t, self.message) for t in self._file_types()}
            # registries with the same definitions share one store: building it (rosbags
            # makes each type's serializer) costs 0.2-0.5 s, and tests make hundreds
            key = (self.dialect, repr(sorted(own.items())))
            # (each step one call under the GIL: a registry of another thread cannot break it)
            store = _shared_stores.pop(key, None)
            if store is None:
                store = _build_store(self.dialect, own)
            _shared_stores[key] = store  # the newest last: the oldest go first
            for old in list(_shared_stores)[:-_SHARED_STORES]:
                _shared_stores.pop(old, None)
            self._typestore = store
        return self._typestore

    def _file_types(self) -> list[MessageType]:
        """Every message type defined by files (parts included) that loads."""
        found: list[MessageType] = []
        for name in [f"{p}/msg/{t}" for p, t in self._files.names("msg")]:
            with suppress(GraphError):
                found.append(self.message(name))
        for name in self.service_names():
            with suppress(GraphError):
                service = self.service(name)
                found += [service.request, service.response]
        for name in self.action_names():
            with suppress(GraphError):
                action = self.action(name)
                found += [action.goal, action.result, action.feedback]
        return found


def codec_for(registry: TypeRegistry, mtype: MessageType) -> WireCodec:
    """The encoder support (typed arrays, wire serialization) of ``mtype`` (cached).

    It implements ``rwt_protocol.ports.MessageCodec`` for CBOR and cbor-raw
    (D21). rwt's own packages use it; the public ``TypeRegistry.serialize``
    gives the bytes without it.
    """
    codecs = registry._codecs
    found = codecs.get(mtype.name)
    if found is None or found.mtype is not mtype:
        found = codecs[mtype.name] = WireCodec(mtype, registry.message, registry.typestore)
    return found


_SHARED_STORES = 4
"""Typestores kept for registries to share (``TypeRegistry.typestore``), the newest."""
_shared_stores: dict[tuple[Dialect, str], Typestore] = {}


def _build_store(dialect: Dialect, own: Mapping[str, object]) -> Typestore:
    """A rosbags typestore: the dialect's stores (``stores_for``), then ``own`` types over them."""
    merged: dict[str, object] = {}
    for fallback in reversed(stores_for(dialect)):
        merged.update(fallback)
    if dialect is Dialect.ROS2:
        merged[WSTRING_TYPE] = WSTRING_DEFINITION
    merged.update(own)
    store = get_typestore(Stores.EMPTY)
    fresh = {k: v for k, v in merged.items() if k not in store.fielddefs}
    store.register(cast("Typesdict", fresh))
    return store
