"""Start-up objects leave the collector's generations; later garbage is still collected."""

from __future__ import annotations

import gc
import sys
import weakref
from collections.abc import Iterator

import pytest

from rwt_transports.process.gcfreeze import freeze_startup_objects


@pytest.fixture
def unfrozen() -> Iterator[None]:
    # Collect what earlier tests of this worker left first, their warnings muted: an
    # unclosed socket of theirs (a ResourceWarning from its finalizer) is not this
    # test's, but the collection in freeze_startup_objects would report it here.
    hook = sys.unraisablehook
    sys.unraisablehook = lambda _: None
    try:
        gc.collect()
    finally:
        sys.unraisablehook = hook
    yield
    gc.unfreeze()


class _Node:
    def __init__(self) -> None:
        self.other: _Node | None = None


def _cycle() -> weakref.ref[_Node]:
    a, b = _Node(), _Node()
    a.other, b.other = b, a
    return weakref.ref(a)


@pytest.mark.usefixtures("unfrozen")
def test_live_objects_are_frozen_and_new_cycles_still_collected() -> None:
    kept = _Node()
    garbage = _cycle()  # unreachable before the freeze: collected, not frozen
    frozen = freeze_startup_objects()
    assert garbage() is None
    # (gc.get_freeze_count() is not compared: a server another test left running in
    # a thread of this process may freeze its own objects meanwhile, or free frozen ones)
    assert frozen > 0
    assert not any(obj is kept for obj in gc.get_objects())  # in the permanent generation
    later = _cycle()
    gc.collect()
    assert later() is None
