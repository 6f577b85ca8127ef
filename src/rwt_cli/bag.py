"""``rwt bag``: inspect, repair, convert and filter bags (info, reindex, convert, filter)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rwt_bag.errors import BagError
from rwt_bag.formats import BagFormat
from rwt_bag.selection import TopicSelection

from .bag_options import (
    EXCLUDE_REGEX_HELP,
    REGEX_HELP,
    ExcludeTopics,
    Patterns,
    fail,
    topic_selection,
)

__all__ = ["bag_app"]


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
        fail("bag info", str(exc))


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
        fail("bag reindex", str(exc))
    dropped = done.dropped_bytes
    tail = f", {dropped} bytes of a cut-short tail dropped" if dropped else ""
    typer.echo(
        f"reindexed {bag}: {done.messages} messages{tail}; the original is {backup_path(bag)}"
    )


BagIn = Annotated[Path, typer.Argument(help="The bag to read (a ROS 1 .bag file, a ROS 2 folder).")]
BagOut = Annotated[Path, typer.Argument(help="The bag to create (*.bag for ros1, else a folder).")]
OutFormat = Annotated[
    BagFormat | None,
    typer.Option(
        "--format",
        help="mcap, sqlite3 or ros1; default: ros1 for an OUT named *.bag, else mcap "
        "(filter: the input's format).",
    ),
]


def _copy(
    command: str,
    src: Path,
    dst: Path,
    fmt: BagFormat | None,
    selection: TopicSelection | None = None,
    start: float | None = None,
    end: float | None = None,
) -> None:
    """Copy ``src`` to ``dst`` (``rwt_bag.convert``) and print one line; errors exit 1."""
    from rwt_bag.convert import bag_format, copy_bag  # noqa: PLC0415 - see record_options

    try:
        if fmt is None:
            default = BagFormat.ROS1 if dst.suffix == ".bag" else BagFormat.MCAP
            fmt = bag_format(src) if command == "filter" else default
        stats = copy_bag([src], dst, fmt, selection=selection, start_s=start, end_s=end)
    except BagError as exc:
        fail(f"bag {command}", str(exc))
    topics = f"{len(stats.topics)} topic{'' if len(stats.topics) == 1 else 's'}"
    typer.echo(f"wrote {stats.messages} messages on {topics} -> {dst}")


@bag_app.command("convert", short_help="Copy a bag into another format (MCAP, sqlite3, ROS 1).")
def convert(src: BagIn, dst: BagOut, fmt: OutFormat = None) -> None:
    """Copy a bag into another format: MCAP, sqlite3 (ROS 2) or ROS 1.

    Between ROS 1 and ROS 2 each message is converted with rosbags (a header's
    seq is dropped or set to 0; latching becomes transient-local QoS and back).
    OUT must not exist.
    """
    _copy("convert", src, dst, fmt)


@bag_app.command("filter", short_help="Copy some topics or a time range of a bag.")
def filter_bag(
    src: BagIn,
    dst: BagOut,
    topics: Patterns = "",
    regex: Annotated[
        str | None, typer.Option("--regex", "-e", metavar="REGEX", help=REGEX_HELP)
    ] = None,
    exclude_regex: Annotated[
        str | None,
        typer.Option("--exclude", "--exclude-regex", metavar="REGEX", help=EXCLUDE_REGEX_HELP),
    ] = None,
    exclude_topics: ExcludeTopics = None,
    start: Annotated[
        float | None,
        typer.Option(
            min=0.0, metavar="SECONDS", help="Copy from this many seconds after the first message."
        ),
    ] = None,
    end: Annotated[
        float | None,
        typer.Option(
            min=0.0, metavar="SECONDS", help="Copy up to this many seconds after the first message."
        ),
    ] = None,
    fmt: OutFormat = None,
) -> None:
    """Copy the chosen topics of a bag, from --start to --end, into a new bag.

    Topics are chosen as rwt record chooses them (--topics globs, --regex, then
    --exclude and --exclude-topics); times count in seconds from the bag's first
    message. OUT must not exist.
    """
    selection = topic_selection(topics, regex, exclude_regex, exclude_topics)
    _copy("filter", src, dst, fmt, selection, start, end)
