"""`rwt record` as a user runs it: its errors are one line, its server's address any form.

An error raised inside the recorder's task groups used to reach the user as
``unhandled errors in a TaskGroup (1 sub-exception)``; it is one line naming the
problem now (``rwt_cli.checks.one_line_errors``). The address takes the forms
``rwt conformance`` and the client take (``rwt_client.connectors.server_url``).
"""

from __future__ import annotations

import functools
import subprocess
from pathlib import Path

import anyio
import pytest
from anyio.streams.buffered import BufferedByteReceiveStream

from tests.support.cli import ENV, RWT, run_rwt, rwt_serve

pytestmark = pytest.mark.anyio

HANG_GUARD_S = 60  # a bound on a hung process, not a speed requirement


async def _rwt(*args: str) -> subprocess.CompletedProcess[str]:
    return await anyio.to_thread.run_sync(functools.partial(run_rwt, *args))


async def test_recording_over_an_existing_bag_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "taken"
    out.mkdir()
    async with rwt_serve("--port", "0") as (_, urls):
        done = await _rwt("record", urls["ws"], str(out), "--duration", "1")
    assert done.returncode == 1
    assert done.stderr == (
        f"rwt record: cannot create the bag {out}: {out} exists already, not overwriting.\n"
    )


async def test_an_unreachable_server_is_one_line(tmp_path: Path) -> None:
    done = await _rwt("record", "tcp://127.0.0.1:1", str(tmp_path / "bag"), "--duration", "1")
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        "rwt record: cannot connect to tcp://127.0.0.1:1: All connection attempts failed"
    ]


async def test_host_and_port_is_a_websocket_server_as_for_rwt_conformance(
    tmp_path: Path,
) -> None:
    bag = tmp_path / "bag"
    async with rwt_serve("--port", "0") as (_, urls):
        done = await _rwt("record", urls["ws"].removeprefix("ws://"), str(bag), "--duration", "1")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("recorded ") and done.stdout.endswith(f"-> {bag}\n")
    assert (bag / "metadata.yaml").is_file()


async def test_a_url_of_another_scheme_is_one_line_naming_the_forms(tmp_path: Path) -> None:
    done = await _rwt("record", "http://127.0.0.1:9090", str(tmp_path / "bag"))
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr == (
        "rwt record: unsupported URL scheme 'http' in 'http://127.0.0.1:9090':"
        " use ws://, wss://, tcp:// or tcp+tls://HOST:PORT, webrtc+http://HOST:PORT/webrtc,"
        " or HOST:PORT\n"
    )


async def test_a_duration_ends_the_recording_when_the_server_vanished(tmp_path: Path) -> None:
    """The recorder's lookups of new topics fail at once while the server is away (the
    client's calls while down), instead of each waiting out its 10 s call timeout."""
    bag = tmp_path / "bag"
    async with rwt_serve("--port", "0", "--log-level", "info") as (server, urls):
        recorder = await anyio.open_process(
            [*RWT, "record", urls["ws"], str(bag), "--duration", "4"],
            env=ENV,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        try:
            assert server.stderr is not None
            log = BufferedByteReceiveStream(server.stderr)
            with anyio.fail_after(HANG_GUARD_S):
                while b"event=connect " not in await log.receive_until(b"\n", 10_000):
                    pass
                while not bag.exists():  # made once the recorder is connected
                    await anyio.sleep(0.05)
            server.kill()  # vanishes: no close frame
            with anyio.fail_after(HANG_GUARD_S):
                await recorder.wait()
            assert recorder.stdout is not None and recorder.stderr is not None
            stdout = (await recorder.stdout.receive()).decode()
            stderr = b""
            with anyio.move_on_after(5):
                async for chunk in recorder.stderr:
                    stderr += chunk
        finally:
            if recorder.returncode is None:
                recorder.kill()
            await recorder.aclose()
    text = stderr.decode()
    assert recorder.returncode == 0, text
    assert stdout.endswith(f"-> {bag}\n")
    assert f"{urls['ws']}: connection closed; reconnecting" in text
    assert f"reason=not connected to {urls['ws']}: " in text  # a lookup while away
    assert "within 10 s" not in text and "Traceback" not in text
    info = await _rwt("bag", "info", str(bag))
    assert info.returncode == 0, info.stderr
