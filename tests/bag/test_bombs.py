"""Decompression bombs: small bags that expand to gigabytes are refused, in bounded memory.

Each bag is a few KB to a MB on disk and decompresses to 256 MiB to 1 GiB of
zeros (which parse as 9-byte empty records): an MCAP zstd or lz4 chunk with an
honest or a lying declared size, many chunks under the chunk cap, a ROS 1 bz2
or lz4 chunk, a zstd row of a per-message compressed sqlite3 bag, and the zstd
storage file of a per-file compressed one. ``rwt bag
info``, ``rwt play`` and ``rwt serve --play`` each exit 1 with one line naming
the bag and the limit (docs/limits.md, Bags), and the process's peak RSS read
from ``/proc/self/status`` stays far below what the bomb expands to.
"""

from __future__ import annotations

import subprocess
import sys
from typing import TYPE_CHECKING

import anyio
import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.cli import run_rwt
from tests.support.realclients import run_python

from .hostile import MIB, mcap_bomb, ros1_bomb, sqlite3_bomb

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

#: Peak RSS allowed to a command refusing a bomb: generous (a bare ``rwt`` takes
#: ~50 MiB; the read budget of the 2 MB lz4 bombs is ~240 MiB, which a decompressor
#: may hold twice), below what the bombs expand to.
RSS_BOUND_KIB = 640 * 1024

# Runs the rwt command line in this process and prints its peak RSS on exit.
_WITH_RSS = """
import atexit, runpy, sys
def peak():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            sys.stderr.write("peak_rss_kib=" + line.split()[1] + "\\n")
atexit.register(peak)
sys.argv = ["rwt", *sys.argv[1:]]
runpy.run_module("rwt", run_name="__main__")
"""

BOMBS: dict[str, tuple[Callable[[Path], Path], bool]] = {  # name: (builder, ROS 1)
    "mcap-zstd-1GiB": (lambda d: mcap_bomb(d / "bomb.mcap", size=1024 * MIB), False),
    "mcap-zstd-lying-size": (
        lambda d: mcap_bomb(d / "bomb.mcap", size=1024 * MIB, declared=4096),
        False,
    ),
    "mcap-zstd-many-chunks": (
        lambda d: mcap_bomb(d / "bomb.mcap", size=9 * MIB, chunks=60),
        False,
    ),
    "mcap-lz4": (lambda d: mcap_bomb(d / "bomb.mcap", size=512 * MIB, compression="lz4"), False),
    # 320 MiB, past the 256 MiB chunk cap
    "ros1-bz2": (lambda d: ros1_bomb(d / "bomb.bag", size=320 * MIB), True),
    "ros1-lz4": (lambda d: ros1_bomb(d / "bomb.bag", size=512 * MIB, compression="lz4"), True),
    "sqlite3-zstd-row": (lambda d: sqlite3_bomb(d / "bomb", size=1024 * MIB), False),
    "sqlite3-zstd-file": (
        lambda d: sqlite3_bomb(d / "bomb", size=1024 * MIB, mode="file"),
        False,
    ),
}


def _rwt(*args: str, cwd: Path) -> tuple[subprocess.CompletedProcess[str], int]:
    """Run ``rwt ARGS``; the result and the peak RSS in KiB."""
    # a hang guard only: the bombs made today's reader run for minutes
    result = run_rwt(*args, cwd=cwd, timeout=120, command=[sys.executable, "-c", _WITH_RSS])
    (peak,) = [ln for ln in result.stderr.splitlines() if ln.startswith("peak_rss_kib=")]
    return result, int(peak.split("=")[1])


def _error_line(result: subprocess.CompletedProcess[str], command: str) -> str:
    (line,) = [ln for ln in result.stderr.splitlines() if ln.startswith(f"rwt {command}: ")]
    return line


@pytest.mark.parametrize("name", list(BOMBS))
def test_bomb_refused_in_bounded_memory(tmp_path: Path, name: str) -> None:
    build, ros1 = BOMBS[name]
    bag = build(tmp_path)
    dialect = ("--dialect", "ros1") if ros1 else ()
    for command, args in (
        ("play", ("play", "--port", "0", *dialect, str(bag))),
        ("bag info", ("bag", "info", str(bag))),
    ):
        result, peak_kib = _rwt(*args, cwd=tmp_path)
        if command == "bag info" and result.returncode == 0:
            # a ROS 1 bag's index (and a sqlite3 bag's metadata) are read without
            # decompressing anything: info answers from them, and that is all it reads
            assert "Messages:          1" in result.stdout
        else:
            assert result.returncode == 1, result.stderr[-2000:]
            line = _error_line(result, command)
            assert str(bag) in line
            assert "decompresses" in line
            assert "docs/limits.md" in line
        assert peak_kib < RSS_BOUND_KIB, f"{command}: peak RSS {peak_kib} KiB"


def test_serve_play_refuses_a_bomb_before_listening(tmp_path: Path) -> None:
    bag = mcap_bomb(tmp_path / "bomb.mcap", size=1024 * MIB)
    result, peak_kib = _rwt("serve", "--port", "0", "--play", str(bag), cwd=tmp_path)
    assert result.returncode == 1
    assert "listening" not in result.stdout
    line = _error_line(result, "serve")
    assert f"{bag}: a chunk decompresses to more than 256 MiB" in line
    assert peak_kib < RSS_BOUND_KIB


@pytest.mark.anyio
async def test_serve_play_without_check_serves_on_after_a_bomb_mid_play(tmp_path: Path) -> None:
    """``--no-play-check``: the bomb is met while playing; playback stops, serving goes on."""
    bag = ros1_bomb(tmp_path / "bomb.bag", size=64 * MIB)  # its index reads without inflating
    args = ("--dialect", "ros1", "--play", str(bag), "--no-play-check")
    server = ServerProcess(tmp_path, args)
    try:
        # the player meets the bomb at its first message: then the server must serve on
        with anyio.fail_after(60):  # a hang guard
            while "event=play_failed" not in server.stderr_text():
                await anyio.sleep(0.05)
        out = await run_python(
            f"""
            import roslibpy
            ros = roslibpy.Ros("127.0.0.1", {server.port})
            ros.run(timeout=20)
            print("/rosapi/topics" in ros.get_services())
            ros.terminate()
            """
        )
    finally:
        assert server.stop() == 0, server.stderr_text()
    assert out.split() == ["True"]
    failed = [ln for ln in server.stderr_text().splitlines() if "event=play_failed" in ln]
    assert len(failed) == 1, failed
    assert f"{bag}: the bag decompresses to more than" in failed[0]
