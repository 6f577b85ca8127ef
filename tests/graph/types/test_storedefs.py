"""The packaged copy of rosbags' store definitions is rosbags' own, to the last type.

``rwt_graph/types/rosbags_stores.json`` holds the field definitions of rosbags'
Jazzy and Noetic stores as data, so a server starts without importing every
rosbags store module back to Dashing. It is used only with the rosbags version
it was taken from; these tests check it gives exactly what that rosbags gives
(the kinds of containers and the node kinds included), and that the registry
reads the same messages either way. After a rosbags upgrade, rewrite it::

    python -m tests.graph.types.test_storedefs
"""

from __future__ import annotations

import json
from importlib.metadata import version

import pytest
from rosbags.typesys import Stores, get_typestore

from rwt_graph.types import Dialect, TypeRegistry, sources

STORES = {"ROS2_JAZZY": Stores.ROS2_JAZZY, "ROS1_NOETIC": Stores.ROS1_NOETIC}


def rosbags_fielddefs(name: str) -> dict[str, object]:
    """The definitions of a store as rosbags itself gives them."""
    return dict(get_typestore(STORES[name]).fielddefs)


def render_json() -> str:
    """The text of the JSON file for the installed rosbags: a line a type."""
    lines = [f'{{"rosbags": {json.dumps(version("rosbags"))}, "stores": {{']
    for index, name in enumerate(STORES):
        lines.append(f"{json.dumps(name)}: {{")
        entries = [f"{json.dumps(k)}: {json.dumps(v)}" for k, v in rosbags_fielddefs(name).items()]
        lines.append(",\n".join(entries))
        lines.append("}," if index < len(STORES) - 1 else "}")
    lines.append("}}")
    return "\n".join(lines) + "\n"


def test_the_copy_is_of_the_installed_rosbags() -> None:
    # a different rosbags: the server reads rosbags' own stores (still correct, slower);
    # this fails so the copy is rewritten
    assert json.loads(sources.PACKAGED_STORES.read_text())["rosbags"] == version("rosbags")
    assert sources.PACKAGED_STORES.read_text() == render_json()


@pytest.mark.parametrize("dialect", list(Dialect))
def test_each_definition_is_rosbags_own(dialect: Dialect) -> None:
    names = ["ROS1_NOETIC", "ROS2_JAZZY"] if dialect is Dialect.ROS1 else ["ROS2_JAZZY"]
    copied = sources.stores_for(dialect)
    # repr tells lists from tuples and Nodetype members from plain ints
    assert [repr(store) for store in copied] == [repr(rosbags_fielddefs(n)) for n in names]
    # each a mapping of its own, as a rosbags typestore's
    assert sources.stores_for(dialect)[0] is not copied[0]


@pytest.mark.parametrize("dialect", list(Dialect))
def test_the_registry_reads_the_same_messages_from_rosbags_stores(
    dialect: Dialect, monkeypatch: pytest.MonkeyPatch
) -> None:
    packaged = TypeRegistry(dialect)
    monkeypatch.setattr(sources, "_packaged_stores", lambda: None)
    from_rosbags = TypeRegistry(dialect)
    names = from_rosbags.message_names()
    assert packaged.message_names() == names
    for name in names:
        mine, theirs = packaged.message(name), from_rosbags.message(name)
        assert (mine.fields, mine.constants, mine.full_text()) == (
            theirs.fields,
            theirs.constants,
            theirs.full_text(),
        )


def test_under_another_rosbags_the_stores_are_rosbags_own(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sources._packaged_stores.cache_clear()
    monkeypatch.setattr(sources, "version", lambda _: "0.0.0")
    try:
        assert sources._packaged_stores() is None
        for dialect, names in ((Dialect.ROS2, ["ROS2_JAZZY"]), (Dialect.ROS1, list(STORES)[::-1])):
            assert [repr(store) for store in sources.stores_for(dialect)] == [
                repr(rosbags_fielddefs(name)) for name in names
            ]
    finally:
        sources._packaged_stores.cache_clear()


if __name__ == "__main__":
    sources.PACKAGED_STORES.write_text(render_json(), encoding="utf-8")
