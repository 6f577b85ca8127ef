"""The ``rwt record`` and ``rwt bag`` commands, and the options ``rwt play`` shares.

The work is in ``rwt_bag``; this module turns options into its objects. Shared
option types (``RecordTopics``, ``Rate``...) are also used by ``rwt serve``'s
``--record`` and ``--play`` options.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, NoReturn

import anyio
import typer

from rwt_bag.errors import BagError
from rwt_bag.formats import BagFormat, SplitPolicy
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.access import parse_glob_list
from rwt_transports.allocator import HEAP_KEEP_MIB, tune_allocator

from .checks import check_directories, check_glob_list

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rwt_bag.jobs import BagJobs, PlayOptions, RecordOptions
    from rwt_graph.graph import Graph

__all__ = [
    "RecordMaxSize",
    "RecordSplit",
    "bag_app",
    "bag_jobs",
    "play_options",
    "record",
    "record_options",
    "split_policy",
]

MB = 1_000_000

Patterns = Annotated[
    str,
    typer.Option(
        "--topics",
        callback=check_glob_list,
        metavar="PATTERNS",
        help="Topics, comma-separated glob patterns (/tf*,/scan); default: all.",
    ),
]
FORMAT_HELP = "mcap, sqlite3 (ROS 2 bags) or ros1 (a ROS 1 graph)."
Format = Annotated[BagFormat, typer.Option(help=FORMAT_HELP)]
SplitSize = Annotated[
    float | None,
    typer.Option(min=0.001, metavar="MB", help="Start a new file after this many megabytes."),
]
SplitDuration = Annotated[
    float | None,
    typer.Option(min=0.001, metavar="SECONDS", help="Start a new file after this many seconds."),
]
DialectOption = Annotated[
    Dialect | None,
    typer.Option(
        help="ROS message dialect (default: ros1 for a ROS 1 bag or recording, else ros2)."
    ),
]

ROS1_BAG_MAGIC = b"#ROSBAG V2.0\n"
"""The first line of every ROS 1 bag file."""


def dialect_for(
    dialect: Dialect | None, bags: Sequence[Path] = (), fmt: BagFormat | None = None
) -> Dialect:
    """The dialect: ``--dialect`` as given, else what the bag says.

    ROS 1 for a ROS 1 bag to play (its file starts with ``ROS1_BAG_MAGIC``) or a
    ``ros1`` recording, ROS 2 otherwise.
    """
    if dialect is not None:
        return dialect
    if fmt is BagFormat.ROS1 or any(_is_ros1_bag(path) for path in bags):
        return Dialect.ROS1
    return Dialect.ROS2


def _is_ros1_bag(path: Path) -> bool:
    try:
        with path.open("rb") as file:
            return file.read(len(ROS1_BAG_MAGIC)) == ROS1_BAG_MAGIC
    except OSError:  # a folder (a ROS 2 bag) or missing: the reader says so later
        return False


Interfaces = Annotated[
    list[Path] | None,
    typer.Option(
        callback=check_directories,
        metavar="DIR",
        help="Extra interface directory (PKG/msg, PKG/srv, PKG/action); repeatable.",
    ),
]
Rate = Annotated[float, typer.Option(min=0.001, help="Playback speed (2: twice as fast).")]
Loop = Annotated[bool, typer.Option(help="Start over at the end of the bag.")]
StartOffset = Annotated[
    float, typer.Option(min=0.0, metavar="SECONDS", help="Start this far into the bag.")
]
Clock = Annotated[
    float | None,
    typer.Option(
        min=0.001,
        metavar="HZ",
        help="Publish /clock at this rate and answer rosapi get_time with bag time.",
    ),
]
StartPaused = Annotated[
    bool, typer.Option(help="Start paused; /rwt/player/resume starts playback.")
]
Check = Annotated[
    bool,
    typer.Option(help="Decode the whole bag before publishing (--no-check: start at once)."),
]
Remap = Annotated[
    list[str] | None,
    typer.Option(
        "--remap",
        "-m",
        metavar="OLD:=NEW",
        help="Publish the bag's topic OLD as NEW (as ros2 bag play); repeatable.",
    ),
]
Delay = Annotated[
    float,
    typer.Option(
        "--delay",
        "-d",
        min=0.0,
        metavar="SECONDS",
        help="Wait this long after advertising before the first message.",
    ),
]
PlaybackDuration = Annotated[
    float | None,
    typer.Option(min=0.0, metavar="SECONDS", help="Play only this much bag time."),
]
PlaybackUntil = Annotated[
    float | None,
    typer.Option(
        "--playback-until-sec",
        metavar="SECONDS",
        help="Play nothing stamped after this bag time (seconds since the epoch).",
    ),
]


def split_policy(size_mb: float | None, duration_s: float | None) -> SplitPolicy:
    """The split policy of ``--split-size``/``--split-duration``."""
    return SplitPolicy(
        max_bytes=None if size_mb is None else int(size_mb * MB), max_seconds=duration_s
    )


RecordMaxSize = Annotated[
    int | None,
    typer.Option(
        min=1,
        metavar="BYTES",
        help="Stop recording (the server goes on) at this many bytes of messages; "
        "with --record-split, start a new part there instead.",
    ),
]
RecordSplit = Annotated[
    bool,
    typer.Option(help="At --record-max-size, start a new part (BAG_1, ...) instead of stopping."),
]


def record_options(
    path: Path | None,
    topics: str,
    fmt: BagFormat,
    split: SplitPolicy,
    *,
    max_size: int | None = None,
    split_at_max: bool = False,
) -> RecordOptions | None:
    """``RecordOptions`` of ``--record`` (None without it).

    ``max_size`` (bytes) stops recording there, or with ``split_at_max`` starts a
    new part there (the smaller of it and ``split.max_bytes``), as ``ros2 bag
    record --max-bag-size`` splits.
    """
    if path is None:
        return None
    from rwt_bag.jobs import RecordOptions  # noqa: PLC0415 - rosbags' writers only when used

    stop_at = max_size
    if max_size is not None and split_at_max:
        part = max_size if split.max_bytes is None else min(split.max_bytes, max_size)
        split = SplitPolicy(max_bytes=part, max_seconds=split.max_seconds)
        stop_at = None
    return RecordOptions(path, parse_glob_list(topics) or ("*",), fmt, split, stop_at)


def play_options(
    paths: list[Path] | None,
    *,
    rate: float,
    loop: bool,
    start_offset: float,
    topics: str,
    clock: float | None,
    check: bool,
    paused: bool = False,
    remap: list[str] | None = None,
    delay: float = 0.0,
    duration: float | None = None,
    until_sec: float | None = None,
) -> PlayOptions | None:
    """``PlayOptions`` of ``--play`` (None without it).

    Raises:
        typer.BadParameter: a ``--remap`` that is not ``OLD:=NEW``, or
            ``--playback-until-sec`` that is not a finite time.
    """
    if not paths:
        return None
    from rwt_bag.jobs import PlayOptions  # noqa: PLC0415 - see record_options

    until_ns = None
    if until_sec is not None:
        if not math.isfinite(until_sec):
            hint = "--playback-until-sec"
            raise typer.BadParameter(f"{until_sec} is not a time", param_hint=hint)
        until_ns = int(until_sec * 1e9)
    return PlayOptions(
        paths,
        rate,
        loop,
        start_offset,
        parse_glob_list(topics),
        clock,
        check,
        paused,
        remap=parse_remaps(remap or []),
        delay=delay,
        duration=duration,
        until_ns=until_ns,
    )


def parse_remaps(rules: list[str]) -> dict[str, str]:
    """``OLD:=NEW`` rules (``ros2 bag play --remap``) as a dict; the last rule for OLD wins.

    Raises:
        typer.BadParameter: a rule without ``:=``, or with an empty side.
    """
    remap = {}
    for rule in rules:
        old, sep, new = rule.partition(":=")
        if not sep or not old.strip() or not new.strip():
            raise typer.BadParameter(f"{rule!r} is not OLD:=NEW", param_hint="--remap")
        remap[old.strip()] = new.strip()
    return remap


def bag_jobs(
    graph: Graph,
    record: RecordOptions | None,
    play: PlayOptions | None,
    *,
    command: str,
    stop_at_end: object = None,
) -> BagJobs | None:
    """The ``BagJobs`` of the options, or None; a bad bag exits with one line (code 1)."""
    if record is None and play is None:
        return None
    from rwt_bag.jobs import BagJobs  # noqa: PLC0415 - see record_options

    try:
        return BagJobs(
            graph,
            record=record,
            play=play,
            progress=sys.stdout if command != "serve" else None,
            stop_at_end=stop_at_end,  # type: ignore[arg-type]
        )
    except BagError as exc:
        _fail(command, str(exc))


def _fail(command: str, message: str) -> NoReturn:
    typer.echo(f"rwt {command}: {message}", err=True)
    raise typer.Exit(1)


def record(
    url: Annotated[str, typer.Argument(help="The rosbridge server: ws://, wss:// or tcp://.")],
    out: Annotated[Path, typer.Argument(help="The bag to create (a folder; a .bag file).")],
    topics: Patterns = "",
    fmt: Annotated[BagFormat, typer.Option("--format", help=FORMAT_HELP)] = BagFormat.MCAP,
    split_size: SplitSize = None,
    split_duration: SplitDuration = None,
    compression: Annotated[
        str, typer.Option(help="Subscription compression: cbor (binary) or none (JSON).")
    ] = "cbor",
    duration: Annotated[
        float | None,
        typer.Option(min=0.001, metavar="SECONDS", help="Stop after recording this long."),
    ] = None,
    dialect: DialectOption = None,
    interfaces: Interfaces = None,
) -> None:
    """Record topics of a rosbridge server into a bag until SIGINT, SIGTERM or --duration.

    Subscribes, as a client, to every topic the server lists (rosapi) that
    matches --topics, also to topics that appear later, and writes each message
    with its receive time and its type's definition. ROS 2 bags stay readable if
    the recorder is killed (up to the last second or so).
    """
    if compression not in ("cbor", "none"):
        _fail("record", f"--compression must be cbor or none, not {compression}")
    from rwt_bag.jobs import record_remote  # noqa: PLC0415 - see record_options

    tune_allocator(HEAP_KEEP_MIB * 1024 * 1024)  # as rwt serve does: images, clouds
    registry = TypeRegistry(dialect_for(dialect, (), fmt), interfaces or ())
    try:
        anyio.run(
            lambda: record_remote(
                url,
                out,
                registry,
                topics=parse_glob_list(topics) or ("*",),
                fmt=fmt,
                split=split_policy(split_size, split_duration),
                compression=compression,
                duration=duration,
            )
        )
    except (BagError, OSError) as exc:
        _fail("record", str(exc))
    except BaseExceptionGroup as group:
        _fail("record", "; ".join(str(e) for e in group.exceptions))


bag_app = typer.Typer(
    no_args_is_help=True,
    rich_markup_mode=None,
    help="Inspect bags (ROS 1, ROS 2 sqlite3 and MCAP).",
)


@bag_app.command("info", short_help="Print a bag's topics, types, counts and duration.")
def info(
    bag: Annotated[list[Path], typer.Argument(help="The bag (several: split parts, as one).")],
) -> None:
    """Print a bag's topics, types, message counts and duration, like ros2 bag info."""
    from rwt_bag.info import bag_info  # noqa: PLC0415 - see record_options

    try:
        typer.echo(bag_info(bag).format())
    except BagError as exc:
        _fail("bag info", str(exc))


@bag_app.command("reindex", short_help="Rebuild the index of a bag cut short (a killed recorder).")
def reindex(
    bag: Annotated[Path, typer.Argument(help="The bag (a ROS 1 .bag file, a ROS 2 bag folder).")],
) -> None:
    """Rebuild the index of a bag whose recorder was killed, like rosbag reindex.

    A ROS 1 bag gets a new index; a ROS 2 bag (MCAP or sqlite3) a complete MCAP
    summary and footer and a new metadata.yaml, as ros2 bag reindex. Every
    complete record is kept and a tail cut short dropped. The original is kept
    next to the bag as NAME.orig.bag (ROS 1) or the folder NAME.orig (ROS 2).
    """
    from rwt_bag.reindex import backup_path  # noqa: PLC0415 - see record_options
    from rwt_bag.reindex import reindex as rebuild  # noqa: PLC0415

    try:
        done = rebuild(bag)
    except (BagError, OSError) as exc:
        _fail("bag reindex", str(exc))
    dropped = done.dropped_bytes
    tail = f", {dropped} bytes of a cut-short tail dropped" if dropped else ""
    typer.echo(
        f"reindexed {bag}: {done.messages} messages{tail}; the original is {backup_path(bag)}"
    )
