"""Where type definitions come from: interface folders and rosbags stores.

Precedence, high to low: the user's interface folders, the packaged ROS 1
overlay (``rwt_graph/interfaces_ros1``, ROS 1 only), the packaged interfaces
(``rwt_graph/interfaces``), then the rosbags store of the dialect. rosbags
stores hold messages only and drop written defaults; :data:`STORE_DEFAULTS`
puts back the ones ROS 2 writes, for when no packaged text overrides them.
They also hold constants apart from fields: :data:`DECLARATION_ORDER` gives
back the ``.msg`` file's order where the constants are not all first.
"""

from __future__ import annotations

import json
from functools import cache
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from rosbags.interfaces import Nodetype

from .msgparse import resolve_base
from .names import Dialect
from .spec import ArrayKind, Constant, FieldSpec, FieldType

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from rosbags.interfaces.typing import FieldDesc, Typesdict

__all__ = [
    "DECLARATION_ORDER",
    "IDL_PLACEHOLDER",
    "KINDS",
    "PACKAGED_STORES",
    "STORE_DEFAULTS",
    "FileIndex",
    "declaration_orders",
    "packaged_dirs",
    "render_text",
    "store_dialects",
    "store_for",
    "store_message",
    "stores_for",
]

KINDS = ("msg", "srv", "action")

#: Defaults written in ROS 2 definitions that rosbags drops (D7).
STORE_DEFAULTS: dict[str, dict[str, object]] = {
    "geometry_msgs/msg/Quaternion": {"w": 1.0},
}

#: The member rosbags (like the IDL) gives a ROS 2 message that has no fields.
IDL_PLACEHOLDER = "structure_needs_at_least_one_member"

_PACKAGE_ROOT = Path(__file__).resolve().parent.parent

#: rosbags' ROS 2 Jazzy and ROS 1 Noetic field definitions as JSON, with the rosbags
#: version they were taken from (see :func:`store_for`).
PACKAGED_STORES = Path(__file__).resolve().parent / "rosbags_stores.json"


#: The declaration order (constant and field names) of the stores' messages whose ``.msg``
#: file does not declare all its constants first: ``types`` for the ROS 2 store, from ROS 2
#: Kilted's files (tests/graph/types/test_declaration_order.py writes it and checks it),
#: ``ros1_types`` for the ROS 1 store, from ROS 1 Noetic's
#: (tests/graph/types/test_ros1_declaration_order.py).
DECLARATION_ORDER = Path(__file__).resolve().parent / "declaration_order.json"

#: The key of each store's orders in :data:`DECLARATION_ORDER`.
_ORDER_SECTION = {Dialect.ROS2: "types", Dialect.ROS1: "ros1_types"}


def packaged_dirs(dialect: Dialect) -> list[Path]:
    """The packaged interface folders for ``dialect``, highest precedence first."""
    names = ["interfaces_ros1", "interfaces"] if dialect is Dialect.ROS1 else ["interfaces"]
    return [_PACKAGE_ROOT / name for name in names]


def store_for(dialect: Dialect) -> Typesdict:
    """The field definitions of the dialect's rosbags store (a fresh mapping).

    ROS 2 uses Jazzy: it is the current long-term release and a superset of
    Humble's types (a few gain fields, such as ``sensor_msgs/Range.variance``;
    an older client simply omits them and gets defaults). ROS 1 uses Noetic.

    They are rosbags' own ``get_typestore(...).fielddefs``. Under the rosbags
    release :data:`PACKAGED_STORES` was taken from they are read from it:
    rosbags makes every store back to Dashing, with a dataclass per type, to
    give one, a fifth of a server's start (tests/graph/types/test_storedefs.py
    checks the copy equals rosbags' own).
    """
    name = "ROS1_NOETIC" if dialect is Dialect.ROS1 else "ROS2_JAZZY"
    packaged = _packaged_stores()
    if packaged is not None:
        return dict(packaged[name])
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415 - another rosbags only

    return get_typestore(Stores[name]).fielddefs


def stores_for(dialect: Dialect) -> list[Typesdict]:
    """The stores' field definitions consulted for messages, first match wins.

    ROS 1 falls back to the ROS 2 store: the packaged ROS 2 interfaces (for
    example ``rcl_interfaces`` services) use ROS 2-only messages, which then
    still resolve, with ROS 1 time spelling.
    """
    return [store_for(origin) for origin in store_dialects(dialect)]


def store_dialects(dialect: Dialect) -> list[Dialect]:
    """Whose store each of :func:`stores_for` is, in the same order."""
    return [Dialect.ROS1, Dialect.ROS2] if dialect is Dialect.ROS1 else [Dialect.ROS2]


@cache
def _packaged_stores() -> dict[str, Typesdict] | None:
    """:data:`PACKAGED_STORES` as rosbags gives it, or None under another rosbags release."""
    data = json.loads(PACKAGED_STORES.read_text(encoding="utf-8"))
    if data["rosbags"] != version("rosbags"):
        return None
    return {
        name: {
            key: (
                [tuple(constant) for constant in consts],
                [(field, _node(node)) for field, node in fields],
            )
            for key, (consts, fields) in store.items()
        }
        for name, store in data["stores"].items()
    }


def _node(node: list[Any]) -> FieldDesc:
    """A field's type node from JSON as rosbags has it: ``(Nodetype, detail)`` tuples."""
    kind, detail = Nodetype(node[0]), node[1]
    if kind is Nodetype.BASE:
        detail = tuple(detail)
    elif kind is not Nodetype.NAME:  # an array or sequence: (element node, size)
        detail = (_node(detail[0]), detail[1])
    return cast("FieldDesc", (kind, detail))


class FileIndex:
    """The interface files found under a list of folders, first folder wins.

    Each folder holds ``<pkg>/msg/*.msg``, ``<pkg>/srv/*.srv`` and
    ``<pkg>/action/*.action``. Folders that do not exist are skipped.

    Args:
        roots: folders in precedence order, highest first.
    """

    def __init__(self, roots: Iterable[Path]) -> None:
        self.files: dict[tuple[str, str, str], Path] = {}
        for root in roots:
            if not root.is_dir():
                continue
            for package in sorted(root.iterdir()):
                for kind in KINDS:
                    folder = package / kind
                    if not folder.is_dir():
                        continue
                    for path in sorted(folder.glob(f"*.{kind}")):
                        self.files.setdefault((package.name, kind, path.stem), path)

    def find(self, package: str, kind: str, name: str) -> Path | None:
        """The file defining ``package/kind/name``, or None."""
        return self.files.get((package, kind, name))

    def names(self, kind: str) -> list[tuple[str, str]]:
        """``(package, type)`` pairs of every file of ``kind``."""
        return [(pkg, name) for (pkg, k, name) in self.files if k == kind]

    def packages(self) -> set[str]:
        """Every package that has at least one file."""
        return {pkg for (pkg, _, _) in self.files}


def _store_type(node: tuple[object, object], dialect: Dialect) -> FieldType:
    kind, detail = node
    if kind == Nodetype.BASE:
        base, bound = cast("tuple[str, int]", detail)
        strings = base in ("string", "wstring") and bound
        return FieldType(base, string_bound=bound if strings else None)
    if kind == Nodetype.NAME:
        package, _, short = str(detail).partition("/msg/")
        resolved, is_message = resolve_base(f"{package}/{short}", package, dialect)
        return FieldType(resolved, is_message)
    element_node, size = cast("tuple[tuple[object, object], int]", detail)
    element = _store_type(element_node, dialect)
    if kind == Nodetype.ARRAY:
        array, length = ArrayKind.FIXED, size
    elif size:
        array, length = ArrayKind.BOUNDED, size
    else:
        array, length = ArrayKind.UNBOUNDED, None
    return FieldType(element.base, element.is_message, array, length, element.string_bound)


def _render(ftype: FieldType, dialect: Dialect) -> str:
    if not ftype.is_message:
        return ftype.spelled()
    package, _, rest = ftype.base.partition("/")
    return ftype.spelled(f"{package}/{rest.rpartition('/')[2]}")


def render_text(
    fields: Sequence[FieldSpec],
    constants: Sequence[Constant],
    dialect: Dialect,
    order: Sequence[str] | None = None,
) -> str:
    """Write ``.msg`` text for fields and constants (types without a source text).

    Args:
        fields: the fields, in declaration order.
        constants: the constants, in declaration order.
        dialect: spells the type names.
        order: every constant and field name in the ``.msg`` file's order; None, or an
            order that names other members or reorders the fields, puts the constants
            first. Clients such as Lichtblick compare an advertised definition with
            their own copy line by line, so the file's order matters
            (docs/foxglove.md).

    Returns:
        One line a constant or field, without a last newline.
    """
    lines = {c.name: f"{c.type} {c.name}={_literal(c.value)}" for c in constants}
    for spec in fields:
        line = f"{_render(spec.type, dialect)} {spec.name}"
        if spec.default is not None:
            line += f" {_literal(spec.default)}"
        lines[spec.name] = line
    if order is None or not _fits(order, fields, lines):
        return "\n".join(lines.values())
    return "\n".join(lines[name] for name in order)


def _fits(order: Sequence[str], fields: Sequence[FieldSpec], lines: dict[str, str]) -> bool:
    """Whether ``order`` names each member once and keeps the fields' own order."""
    names = set(order)
    if len(names) != len(order) or names != lines.keys():
        return False
    field_names = {spec.name for spec in fields}
    return [name for name in order if name in field_names] == [spec.name for spec in fields]


@cache
def declaration_orders(store: Dialect = Dialect.ROS2) -> dict[str, tuple[str, ...]]:
    """:data:`DECLARATION_ORDER` of ``store``'s store: ``{"pkg/msg/Type": (member names)}``."""
    data = json.loads(DECLARATION_ORDER.read_text(encoding="utf-8"))
    return {key: tuple(names) for key, names in data[_ORDER_SECTION[store]].items()}


def _literal(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, bytes):
        value = list(value)
    if isinstance(value, list):
        return "[" + ", ".join(_literal(item) for item in value) + "]"
    return str(value)


def store_message(
    store: Typesdict, key: str, dialect: Dialect, origin: Dialect | None = None
) -> tuple[tuple[FieldSpec, ...], tuple[Constant, ...], str] | None:
    """Read a message from a store's field definitions by its key (``pkg/msg/Type``).

    Args:
        store: a store's field definitions (:func:`store_for`).
        key: the message's key in it.
        dialect: the graph's dialect, which spells the text.
        origin: whose store it is (``dialect`` when None): its files' order of
            constants and fields is kept (:data:`DECLARATION_ORDER`).

    Returns:
        ``(fields, constants, text)``, with :data:`STORE_DEFAULTS` applied, or
        None when the store lacks the type.
    """
    definition = store.get(key)
    if definition is None:
        return None
    consts, fielddefs = definition
    defaults = STORE_DEFAULTS.get(key, {}) if dialect is Dialect.ROS2 else {}
    fields = tuple(
        FieldSpec(name, _store_type(node, dialect), defaults.get(name))
        for name, node in fielddefs
        if name != IDL_PLACEHOLDER
    )
    constants = tuple(Constant(name, ctype, value) for name, ctype, value in consts)
    # the order of the files the store was made from (Kilted's or Noetic's)
    order = declaration_orders(origin or dialect).get(key)
    # ends with a newline, as a .msg file does (ROS 1's full text keeps each file's last one)
    return fields, constants, render_text(fields, constants, dialect, order) + "\n"
