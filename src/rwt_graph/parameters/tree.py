"""The ROS 1 parameter tree: global names, namespaces as ``FrozenNamespace`` values.

The tree is never changed in place: a change rebuilds the namespaces on the way
to the name it sets (each a copy of one namespace's entries), so a namespace a
reader got (``get("/robot")``, a watcher's value) stays as it was. Beside the
tree an index holds each *terminal* (a leaf, or a namespace with no entries)
with its size (``value_size`` of the value and of its last name token), so the
store counts parameters and bytes, and finds what a change replaces, in time of
what the change touches (docs/limits.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

from .values import EMPTY_NAMESPACE, FrozenNamespace, ParameterNotSetError, value_size

if TYPE_CHECKING:
    from collections.abc import Iterator

    from .values import ParamValue

__all__ = ["MISSING", "Ros1Tree", "tokens_of"]

MISSING = object()


def tokens_of(key: str) -> list[str]:
    """The tokens of a resolved global name (``/a/b`` -> ``["a", "b"]``; ``/`` -> ``[]``)."""
    return [token for token in key.split("/") if token]


def _join(prefix: str, token: str) -> str:
    return f"{prefix}/{token}" if prefix != "/" else f"/{token}"


def _terminals(value: object, key: str) -> Iterator[tuple[str, object]]:
    """The terminals of ``value`` set at ``key``: leaves and empty namespaces, by name."""
    if isinstance(value, Mapping) and (value or key == "/"):
        for token, item in value.items():
            yield from _terminals(item, _join(key, token))
    else:
        yield key, value


def _size(key: str, value: object) -> int:
    return value_size(value) + value_size(key.rpartition("/")[2])


class Ros1Tree:
    """One ROS 1 parameter tree and its index of terminals (see the module text)."""

    def __init__(self) -> None:
        self.root: FrozenNamespace = EMPTY_NAMESPACE
        self.sizes: dict[str, int] = {}  # terminal -> its size
        self.hollow: set[str] = set()  # the terminals that are empty namespaces
        self.bytes = 0

    def lookup(self, key: str) -> object:
        """The value at ``key`` (a namespace gives the ``FrozenNamespace``), else ``MISSING``."""
        node: object = self.root
        for token in tokens_of(key):
            if not isinstance(node, Mapping) or token not in node:
                return MISSING
            node = node[token]
        return node

    def names(self) -> list[str]:
        """Every leaf's global name, sorted (empty namespaces are no parameter names)."""
        return sorted(key for key in self.sizes if key not in self.hollow)

    def replaced(self, key: str) -> list[str]:
        """The terminals a set or delete of ``key`` removes.

        Those at or under ``key``, and a leaf on the way to it (setting ``/a/b``
        makes a leaf ``/a`` a namespace).
        """
        tokens = tokens_of(key)
        path = ""
        found: list[str] = []
        for token in tokens[:-1]:
            path = f"{path}/{token}"
            if path in self.sizes:
                found.append(path)
        old = self.lookup(key)
        if old is not MISSING:
            found += [name for name, _ in _terminals(old, key) if name in self.sizes]
        return found

    def added(self, key: str, value: ParamValue) -> dict[str, int]:
        """The terminals ``value`` set at ``key`` holds, with their sizes."""
        return {name: _size(name, item) for name, item in _terminals(value, key)}

    def set(self, key: str, value: ParamValue, removed: list[str], added: dict[str, int]) -> None:
        """Put ``value`` at ``key``; ``removed`` and ``added`` from ``replaced`` and ``added``."""
        self._forget(removed)
        for name, item in _terminals(value, key):
            self.sizes[name] = added[name]
            self.bytes += added[name]
            if isinstance(item, Mapping):
                self.hollow.add(name)
        tokens = tokens_of(key)
        if not tokens:
            assert isinstance(value, FrozenNamespace)
            self.root = value
        else:
            self.root = self._rebuilt(self.root, tokens, value)

    def delete(self, key: str) -> list[str]:
        """Remove ``key`` (a leaf or a namespace; ``/`` empties the tree).

        Returns:
            The terminals removed (a namespace left empty becomes one, not returned).

        Raises:
            ParameterNotSetError: nothing is set at ``key``.
        """
        tokens = tokens_of(key)
        if tokens and self.lookup(key) is MISSING:
            raise ParameterNotSetError(f"parameter {key} is not set")
        removed = self.replaced(key) if tokens else list(self.sizes)
        self._forget(removed)
        if not tokens:
            self.root = EMPTY_NAMESPACE
            return removed
        self.root = self._rebuilt(self.root, tokens, MISSING)
        parent = "/" + "/".join(tokens[:-1])
        if len(tokens) > 1 and self.lookup(parent) == {}:  # now an empty namespace: a terminal
            self.sizes[parent] = _size(parent, EMPTY_NAMESPACE)
            self.bytes += self.sizes[parent]
            self.hollow.add(parent)
        return removed

    def _forget(self, removed: list[str]) -> None:
        for name in removed:
            self.bytes -= self.sizes.pop(name)
            self.hollow.discard(name)

    def _rebuilt(
        self, node: Mapping[str, object], tokens: list[str], value: object
    ) -> FrozenNamespace:
        """``node`` with ``value`` at ``tokens`` (``MISSING``: without it), rebuilt on the way."""
        entries = dict(node)
        token = tokens[0]
        if len(tokens) > 1:
            child = entries.get(token)
            inner = child if isinstance(child, Mapping) else EMPTY_NAMESPACE
            entries[token] = self._rebuilt(inner, tokens[1:], value)
        elif value is MISSING:
            del entries[token]
        else:
            entries[token] = value
        return FrozenNamespace(entries)
