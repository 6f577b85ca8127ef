"""``rwt bag reindex`` of decompression bombs: refused with one line, within the read limits.

Reindexing decompresses every chunk, so it is bounded like any read of a bag
(docs/limits.md): a few-KB bag that expands to gigabytes is refused at once,
and the original is left as it was, with no backup and no half-written bag.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from rwt_bag import BagError
from rwt_bag.reindex import reindex

from .hostile import MIB, mcap_bomb, ros1_bomb

if TYPE_CHECKING:
    from pathlib import Path


def test_a_ros1_bomb_is_refused(tmp_path: Path) -> None:
    bag = ros1_bomb(tmp_path / "bomb.bag", size=64 * MIB)  # past 16 MiB + 100 x its size
    before = bag.read_bytes()
    with pytest.raises(BagError, match="decompresses to more than"):
        reindex(bag)
    assert bag.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bomb.bag"]


def test_an_mcap_bomb_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "bomb"
    folder.mkdir()
    mcap_bomb(folder / "bomb.mcap", size=512 * MIB)
    with pytest.raises(BagError, match="decompresses to more than"):
        reindex(folder)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bomb"]
    assert sorted(p.name for p in folder.iterdir()) == ["bomb.mcap"]
