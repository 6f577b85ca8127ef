"""Keyboard controls of ``rwt play`` on a terminal, as ``ros2 bag play`` has them.

=============  ==========================================
key            does
=============  ==========================================
space          pause / resume
right arrow    while paused, publish the next message
up arrow       play 10 % faster (up to ``rwt_graph.playback.MAX_RATE``)
down arrow     play 10 % slower (down to ``MIN_RATE``)
=============  ==========================================

The terminal is put in cbreak mode (keys arrive one by one, unechoed; Ctrl-C
still interrupts) for as long as the controls run, and restored after.
"""

from __future__ import annotations

import contextlib
import logging
import os
import termios
import tty
from typing import TYPE_CHECKING

import anyio

from rwt_graph.playback import MAX_RATE, MIN_RATE

logger = logging.getLogger("rwt.bag")

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from .player import Player

__all__ = ["HELP", "keyboard_controls"]

#: What the keys do, printed once when the controls start.
HELP = "keys: space pause/resume, right arrow next message, up/down arrows rate +/-10%"
_RATE_STEP = 1.1


def _actions(player: Player) -> dict[bytes, Callable[[], object]]:
    def toggle() -> None:
        if player.paused:
            player.resume()
        else:
            player.pause()

    # held down, a key stops at the player's bounds instead of raising past them
    def faster() -> None:
        player.set_rate(min(player.rate * _RATE_STEP, MAX_RATE))

    def slower() -> None:
        player.set_rate(max(player.rate / _RATE_STEP, MIN_RATE))

    return {
        b" ": toggle,
        b"\x1b[C": player.play_next,  # right arrow (ANSI cursor keys, both modes)
        b"\x1bOC": player.play_next,
        b"\x1b[A": faster,  # up
        b"\x1bOA": faster,
        b"\x1b[B": slower,  # down
        b"\x1bOB": slower,
    }


def _keys(data: bytes) -> Iterator[bytes]:
    """The keys in ``data``: escape sequences of three bytes, else single bytes."""
    index = 0
    while index < len(data):
        size = 3 if data[index : index + 1] == b"\x1b" and len(data) >= index + 3 else 1
        yield data[index : index + size]
        index += size


async def keyboard_controls(player: Player, fd: int) -> None:
    """Drive ``player`` with the keys typed on the terminal ``fd`` until cancelled.

    A terminal that refuses cbreak mode (not a terminal after all, or one the
    process may not change) leaves playback without keys, with one log line.
    """
    actions = _actions(player)
    try:
        saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
    except (termios.error, OSError) as exc:
        logger.warning("event=play_keys_off reason=%s (no keyboard controls)", exc)
        return
    try:
        while True:
            await anyio.wait_readable(fd)
            data = os.read(fd, 64)
            if not data:  # the terminal went away
                return
            for key in _keys(data):
                action = actions.get(key)
                if action is not None:
                    action()
    finally:
        with contextlib.suppress(termios.error, OSError):  # the terminal may be gone
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)
