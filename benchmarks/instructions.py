"""``python -m benchmarks.instructions``: instructions a Foxglove burst costs, per message.

Timings on a shared host move by half from one second to the next; instruction
counts do not. This runs rwt's robot of ``benchmarks.foxglove`` (``rwt.Graph``
publishers served by ``rwt.RosbridgeServer``, packing and publishing 100 B
``String`` CDR, a yield every ``--yield-every`` messages, ``BATCH`` by default)
under valgrind's callgrind twice, with a short and a long burst to ``--readers``
Foxglove readers in another process (not counted), and prints the difference
over the extra messages: what one message costs the robot's process, start-up
and set-up left out. Instructions are not time (cache misses and system calls
are not in them), but a change that removes instructions from this path removes
them from every burst
(benchmarks/JOURNAL.md, "Foxglove bursts, round 4").

    python -m benchmarks.instructions [--readers 1] [--yield-every 100] [--base-src /tmp/base/src]

Needs valgrind (``apt-get install valgrind``). The robot runs as ``python -S``
with this interpreter's ``sys.path``: a ``.pth`` file that registers an exit
hook stops callgrind from writing its totals.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from .foxglove import BATCH

ROOT = Path(__file__).resolve().parent.parent
SHORT, LONG = 2_000, 6_000


def _robot() -> None:
    """The counted process: a burst of ``N`` messages to ``READERS`` readers, then exit."""
    import asyncio  # noqa: PLC0415

    import anyio  # noqa: PLC0415

    import rwt  # noqa: PLC0415

    from .foxglove import BURST, _cdr_string, _text  # noqa: PLC0415

    count, readers = int(os.environ["N"]), int(os.environ["READERS"])
    batch = int(os.environ["YIELD_EVERY"])

    async def main() -> None:
        graph = rwt.Graph()
        publisher = graph.create_publisher(BURST, "std_msgs/msg/String")
        server = rwt.RosbridgeServer(graph, rwt.ServerConfig(port=0))
        async with anyio.create_task_group() as tg:
            await tg.start(server.serve)
            port = server.urls["websocket"].rsplit(":", 1)[1]
            cmd = [os.environ["READER_PYTHON"], "-m", "benchmarks.foxglove", "reader"]
            cmd += [f"--port={port}", f"--topic={BURST}", f"--readers={readers}"]
            cmd += [f"--expect={count}", "--idle=5"]
            reader = subprocess.Popen(  # noqa: ASYNC220 (returns at once; read in a thread)
                cmd,
                cwd=ROOT,
                stdout=subprocess.PIPE,
                text=True,
                env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
            )
            assert reader.stdout is not None
            await anyio.to_thread.run_sync(reader.stdout.readline)  # connected
            while len(graph.port.topics[BURST].subscribers) < readers:  # noqa: ASYNC110
                await anyio.sleep(0.01)
            for index in range(count):
                publisher.publish(_cdr_string(_text(index, 100)))
                if (index + 1) % batch == 0:
                    await asyncio.sleep(0)
            done = json.loads(await anyio.to_thread.run_sync(reader.stdout.readline))
            if sum(done["counts"]) != count * readers:
                raise SystemExit(f"lost messages: {done}")
            server.stop()
            tg.cancel_scope.cancel()

    anyio.run(main)


def _count(messages: int, readers: int, src: str | None, batch: int) -> int:
    """Instructions of one robot process (callgrind's total)."""
    path = ([src] if src else []) + [p for p in sys.path if p] + [str(ROOT)]
    env = dict(os.environ, N=str(messages), READERS=str(readers), PYTHONHASHSEED="0")
    env["YIELD_EVERY"] = str(batch)
    env["READER_PYTHON"] = sys.executable
    env["PYTHONPATH"] = os.pathsep.join(path)
    cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null"]
    cmd += [sys.executable, "-S", "-m", "benchmarks.instructions", "robot"]
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    found = re.search(r"refs:\s+([\d,]+)", out.stderr)
    if found is None:
        raise SystemExit(f"no total from callgrind:\n{out.stderr[-2000:]}")
    return int(found.group(1).replace(",", ""))


def per_message(readers: int, src: str | None = None, batch: int = BATCH) -> int:
    """Instructions one message of a burst costs (``LONG`` less ``SHORT`` runs)."""
    long, short = _count(LONG, readers, src, batch), _count(SHORT, readers, src, batch)
    return (long - short) // (LONG - SHORT)


def main(argv: list[str]) -> int:
    """Print the instructions per message of this checkout (and of ``--base-src``)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.instructions")
    parser.add_argument("--readers", type=int, default=1)
    parser.add_argument(
        "--yield-every", type=int, default=BATCH, help="messages between the robot's yields"
    )
    parser.add_argument("--base-src", help="another commit's src directory, counted too")
    args = parser.parse_args(argv)
    if shutil.which("valgrind") is None:
        print("valgrind is not installed (apt-get install valgrind)", file=sys.stderr)
        return 2
    here = per_message(args.readers, str(ROOT / "src"), args.yield_every)
    print(f"this checkout: {here:,} instructions a message to {args.readers} reader(s)")
    if args.base_src:
        base = per_message(args.readers, str(Path(args.base_src).resolve()), args.yield_every)
        print(f"base: {base:,}; this/base {here / base:.3f}")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["robot"]:
        _robot()
        sys.exit(0)
    sys.exit(main(sys.argv[1:]))
