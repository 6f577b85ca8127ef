"""What ``rwt record`` and ``rwt play`` show: a live line on a terminal, a summary otherwise.

On a terminal a rich status line is redrawn a few times a second (messages,
bytes, rate, elapsed and, when playing, remaining time); when the output is not
a terminal (a log, a pipe) nothing is drawn and one summary line is printed at
the end, so logs stay readable.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import anyio
from rich.console import Console
from rich.live import Live
from rich.text import Text

if TYPE_CHECKING:
    from typing import TextIO

    from .player import Player
    from .recorder import Recorder

__all__ = ["play_line", "record_line", "show_progress"]


def _bytes(size: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    raise AssertionError  # pragma: no cover - the loop returns


def _clock(seconds: float) -> str:
    minutes, secs = divmod(max(0.0, seconds), 60)
    return f"{int(minutes):d}:{secs:04.1f}"


def record_line(recorder: Recorder, *, final: bool = False) -> str:
    """One line on a recorder: messages, bytes, rates, elapsed (and drops)."""
    stats = recorder.stats
    elapsed = max(time.monotonic() - stats.started, 1e-9)
    head = "recorded" if final else "recording"
    line = (
        f"{head} {stats.messages} messages ({_bytes(stats.bytes)}) on {len(stats.topics)} "
        f"topics in {_clock(elapsed)}: {stats.messages / elapsed:.0f} msg/s, "
        f"{_bytes(stats.bytes / elapsed)}/s"
    )
    if stats.dropped:
        line += f", {stats.dropped} dropped (disk too slow)"
    if final:
        line += f" -> {', '.join(str(p) for p in recorder.paths)}"
    return line


def play_line(player: Player, *, final: bool = False) -> str:
    """One line on a player: messages, position, remaining time at its rate."""
    stats = player.stats
    position = player.position_s
    remaining = max(0.0, player.duration_s - position) / player.rate
    state = "paused" if player.paused else ("played" if final else "playing")
    line = (
        f"{state} {stats.messages} messages, {_clock(position)} of "
        f"{_clock(player.duration_s)} at {player.rate:g}x"
    )
    if not final:
        line += f", {_clock(remaining)} left"
    if stats.loops and player.loop:
        line += f", loop {stats.loops + 1}"
    return line


async def show_progress(line: Callable[..., str], out: TextIO, *, interval_s: float = 0.25) -> None:
    """Redraw ``line()`` on a terminal until cancelled; then print ``line(final=True)``.

    Off a terminal only the final line is printed.
    """
    console = Console(file=out)
    try:
        if console.is_terminal:
            with Live(Text(line()), console=console, transient=True, auto_refresh=False) as live:
                while True:
                    await anyio.sleep(interval_s)
                    live.update(Text(line()), refresh=True)
        else:
            await anyio.sleep_forever()
    finally:
        print(line(final=True), file=out, flush=True)


if TYPE_CHECKING:
    from collections.abc import Callable
