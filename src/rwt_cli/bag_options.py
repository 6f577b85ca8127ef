"""The options of recording and playback, shared by ``rwt record``, ``play`` and ``serve``.

The work is in ``rwt_bag``; this module turns options into its objects. The
option types (``Rate``, ``MaxBagSize``...) are those of ``rwt record`` and ``rwt
play``, and of ``rwt serve``'s ``--record-...`` and ``--play...`` options.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, NoReturn

import typer

from rwt_bag.errors import BagError
from rwt_bag.formats import BagFormat, ChunkCompression, Compression, SplitPolicy, is_ros1_bag
from rwt_bag.selection import TopicSelection
from rwt_graph.types import Dialect

from .checks import check_directories, check_glob_list

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rwt_bag.jobs import BagJobs, PlayOptions, RecordOptions
    from rwt_graph.graph import Graph

__all__ = [
    "ChunkCompressionLevel",
    "ChunkCompressionOption",
    "DisableKeyboardControls",
    "ExcludeRegex",
    "ExcludeTopics",
    "MaxBagDuration",
    "MaxBagSize",
    "Prefix",
    "RecordMaxSize",
    "RecordSplit",
    "RegexOption",
    "RepeatLatched",
    "WaitForSubscribers",
    "WaitTimeout",
    "bag_jobs",
    "chunk_compression",
    "fail",
    "play_options",
    "record_options",
    "split_policy",
    "terminal_keys",
    "topic_selection",
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
REGEX_HELP = "Also take topics this regular expression finds in the name (re.search)."
EXCLUDE_REGEX_HELP = "Leave out topics this regular expression finds in the name."
EXCLUDE_TOPICS_HELP = "Leave out these topics: comma-separated exact names; repeatable."
RegexOption = Annotated[str | None, typer.Option(metavar="REGEX", help=REGEX_HELP)]
ExcludeRegex = Annotated[str | None, typer.Option(metavar="REGEX", help=EXCLUDE_REGEX_HELP)]
ExcludeTopics = Annotated[
    list[str] | None, typer.Option(metavar="TOPICS", help=EXCLUDE_TOPICS_HELP)
]
MaxBagSize = Annotated[
    int | None,
    typer.Option(
        min=1, metavar="BYTES", help="Start a new file past this many bytes (as ros2 bag record)."
    ),
]
MaxBagDuration = Annotated[
    float | None,
    typer.Option(
        min=0.001,
        metavar="SECONDS",
        help="Start a new file past this many seconds (as ros2 bag record).",
    ),
]
ChunkCompressionOption = Annotated[
    ChunkCompression,
    typer.Option(help="Compress MCAP chunks: none, zstd or lz4 (MCAP bags only)."),
]
ChunkCompressionLevel = Annotated[
    int | None,
    typer.Option(
        metavar="LEVEL",
        help="The chunk compression's level: zstd -7 to 22 (default 3), lz4 0 to 16 (default 0).",
    ),
]
RepeatLatched = Annotated[
    bool,
    typer.Option(
        help="Start each split part with the last message of every latched topic "
        "(as rosbag record --repeat-latched)."
    ),
]
FORMAT_HELP = "mcap, sqlite3 (ROS 2 bags) or ros1 (a ROS 1 graph)."
Format = Annotated[BagFormat, typer.Option(help=FORMAT_HELP)]
# the options of before --max-bag-size/--max-bag-duration, kept for old command lines
SplitSize = Annotated[
    float | None,
    typer.Option(min=0.001, metavar="MB", hidden=True, help="--max-bag-size in megabytes."),
]
SplitDuration = Annotated[
    float | None,
    typer.Option(min=0.001, metavar="SECONDS", hidden=True, help="--max-bag-duration."),
]
DialectOption = Annotated[
    Dialect | None,
    typer.Option(
        help="ROS message dialect (default: ros1 for a ROS 1 bag or recording, else ros2)."
    ),
]


def dialect_for(
    dialect: Dialect | None, bags: Sequence[Path] = (), fmt: BagFormat | None = None
) -> Dialect:
    """The dialect: ``--dialect`` as given, else what the bag says.

    ROS 1 for a ROS 1 bag to play (its file starts with ``rwt_bag.formats.ROS1_MAGIC``) or a
    ``ros1`` recording, ROS 2 otherwise.
    """
    if dialect is not None:
        return dialect
    if fmt is BagFormat.ROS1 or any(is_ros1_bag(path) for path in bags):
        return Dialect.ROS1
    return Dialect.ROS2


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

Prefix = Annotated[
    str,
    typer.Option(
        metavar="NAMESPACE",
        help="Publish every topic under this namespace (/sim: /tf as /sim/tf), as rosbag play.",
    ),
]
WaitForSubscribers = Annotated[
    bool,
    typer.Option(help="Before the first message, wait until every played topic has a subscriber."),
]
WaitTimeout = Annotated[
    float | None,
    typer.Option(
        min=0.0,
        metavar="SECONDS",
        help="Wait this long for them at most, then play anyway; default: until interrupted.",
    ),
]

DisableKeyboardControls = Annotated[
    bool,
    typer.Option(
        help="Ignore the keys (on a terminal: space pauses and resumes, right arrow "
        "publishes the next message while paused, up/down arrows change the rate)."
    ),
]


def terminal_keys(disabled: bool) -> int | None:
    """The descriptor of standard input if keys may drive playback: a terminal, not disabled."""
    if disabled or sys.stdin is None or not sys.stdin.isatty():
        return None
    return sys.stdin.fileno()


def split_policy(
    max_bytes: int | None,
    max_seconds: float | None,
    *,
    size_mb: float | None = None,
    duration_s: float | None = None,
    prefix: str = "",
) -> SplitPolicy:
    """The split policy of ``--max-bag-size``/``--max-bag-duration``.

    ``size_mb`` and ``duration_s`` are the older ``--split-size`` (megabytes) and
    ``--split-duration``, which say the same; ``prefix`` names the options
    (``--record-`` on ``rwt serve``) in errors.

    Raises:
        typer.BadParameter: a limit given under both names.
    """
    for new, old, value, legacy in (
        ("max-bag-size", "split-size", max_bytes, size_mb),
        ("max-bag-duration", "split-duration", max_seconds, duration_s),
    ):
        if value is not None and legacy is not None:
            hint = f"--{prefix}{new}"
            raise typer.BadParameter(f"give --{prefix}{new} or --{prefix}{old}", param_hint=hint)
    if size_mb is not None:
        max_bytes = int(size_mb * MB)
    return SplitPolicy(max_bytes=max_bytes, max_seconds=duration_s or max_seconds)


def topic_selection(
    topics: str,
    regex: str | None = None,
    exclude_regex: str | None = None,
    exclude_topics: list[str] | None = None,
    *,
    prefix: str = "",
) -> TopicSelection:
    """The ``TopicSelection`` of ``--topics``, ``--regex`` and the two exclusions.

    Raises:
        typer.BadParameter: an expression that is not a regular expression.
    """
    from rwt_protocol.runtime.access import parse_glob_list  # noqa: PLC0415 - see checks

    excluded = [name.strip() for item in exclude_topics or () for name in item.split(",")]
    try:
        return TopicSelection.of(
            parse_glob_list(topics),
            regex=regex,
            exclude_regex=exclude_regex,
            exclude_topics=[name for name in excluded if name],
            option_prefix=prefix,
        )
    except BagError as exc:
        raise typer.BadParameter(str(exc)) from None


def chunk_compression(
    algorithm: ChunkCompression, level: int | None, *, prefix: str = ""
) -> Compression:
    """The ``Compression`` of ``--chunk-compression`` and its level.

    Raises:
        typer.BadParameter: a level outside the algorithm's range, or without one.
    """
    try:
        return Compression(algorithm, level)
    except BagError as exc:
        hint = f"--{prefix}chunk-compression-level"
        raise typer.BadParameter(str(exc), param_hint=hint) from None


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
    selection: TopicSelection,
    fmt: BagFormat,
    split: SplitPolicy,
    *,
    max_size: int | None = None,
    split_at_max: bool = False,
    compression: Compression | None = None,
    repeat_latched: bool = True,
    prefix: str = "",
) -> RecordOptions | None:
    """``RecordOptions`` of ``--record`` (None without it).

    ``max_size`` (bytes) stops recording there, or with ``split_at_max`` starts a
    new part there (the smaller of it and ``split.max_bytes``), as ``ros2 bag
    record --max-bag-size`` splits.

    ``prefix`` names the options in errors (``record-`` on ``rwt serve``).

    Raises:
        typer.BadParameter: a chunk compression for a format other than MCAP.
    """
    if path is None:
        return None
    compression = compression or Compression()
    try:
        compression.check_format(fmt)
    except BagError as exc:
        hint = f"--{prefix}chunk-compression"
        raise typer.BadParameter(f"{exc} (--{prefix}format mcap)", param_hint=hint) from None
    from rwt_bag.jobs import RecordOptions  # noqa: PLC0415 - rosbags' writers only when used

    stop_at = max_size
    if max_size is not None and split_at_max:
        part = max_size if split.max_bytes is None else min(split.max_bytes, max_size)
        split = SplitPolicy(max_bytes=part, max_seconds=split.max_seconds)
        stop_at = None
    return RecordOptions(path, selection, fmt, split, stop_at, compression, repeat_latched)


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
    prefix: str = "",
    wait_for_subscribers: bool = False,
    wait_timeout: float | None = None,
) -> PlayOptions | None:
    """``PlayOptions`` of ``--play`` (None without it).

    Raises:
        typer.BadParameter: a ``--remap`` that is not ``OLD:=NEW``, or
            ``--playback-until-sec`` that is not a finite time.
    """
    if not paths:
        return None
    from rwt_bag.jobs import PlayOptions  # noqa: PLC0415 - see record_options
    from rwt_protocol.runtime.access import parse_glob_list  # noqa: PLC0415 - see checks

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
        prefix=prefix,
        wait_for_subscribers=wait_for_subscribers,
        wait_timeout=wait_timeout,
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
    keyboard: int | None = None,
) -> BagJobs | None:
    """The ``BagJobs`` of the options, or None; a bad bag exits with one line (code 1).

    ``keyboard``: the terminal whose keys drive the player (``rwt_bag.keys``).
    """
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
            keyboard=keyboard,
        )
    except BagError as exc:
        fail(command, str(exc))


def fail(command: str, message: str) -> NoReturn:
    """Exit 1 with ``rwt COMMAND: MESSAGE`` on stderr."""
    typer.echo(f"rwt {command}: {message}", err=True)
    raise typer.Exit(1)
