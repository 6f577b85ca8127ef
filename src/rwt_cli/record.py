"""``rwt record``: topics of a rosbridge server, as its client, into a bag."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import anyio
import typer

from rwt_bag.errors import BagError
from rwt_bag.formats import BagFormat, ChunkCompression
from rwt_graph.types import TypeRegistry
from rwt_protocol.errors import RwtError
from rwt_transports.process.allocator import HEAP_KEEP_MIB, tune_allocator

from .bag_options import (
    FORMAT_HELP,
    REGEX_HELP,
    ChunkCompressionLevel,
    DialectOption,
    ExcludeRegex,
    ExcludeTopics,
    Interfaces,
    MaxBagDuration,
    MaxBagSize,
    Patterns,
    RepeatLatched,
    SplitDuration,
    SplitSize,
    chunk_compression,
    dialect_for,
    fail,
    record_options,
    split_policy,
    topic_selection,
)
from .checks import check_server_url, one_line_errors

__all__ = ["RECORD_ERRORS", "record"]

RECORD_ERRORS: tuple[type[BaseException], ...] = (BagError, OSError, RwtError)
"""What ends a recording that the user can fix: the bag (it exists, the disk), the
server (unreachable: ``ConnectionClosedError``, an ``RwtError`` and ``OSError``)."""


def record(
    url: Annotated[
        str,
        typer.Argument(
            callback=check_server_url,
            help="Server: ws://, wss://, tcp:// or tcp+tls://HOST:PORT,"
            " webrtc+http://HOST:PORT/webrtc, or HOST:PORT.",
        ),
    ],
    out: Annotated[Path, typer.Argument(help="The bag to create (a folder; a .bag file).")],
    topics: Patterns = "",
    regex: Annotated[
        str | None, typer.Option("--regex", "-e", metavar="REGEX", help=REGEX_HELP)
    ] = None,
    exclude_regex: ExcludeRegex = None,
    exclude_topics: ExcludeTopics = None,
    fmt: Annotated[BagFormat, typer.Option("--format", help=FORMAT_HELP)] = BagFormat.MCAP,
    max_bag_size: MaxBagSize = None,
    max_bag_duration: MaxBagDuration = None,
    split_size: SplitSize = None,
    split_duration: SplitDuration = None,
    chunk_compression_algorithm: Annotated[
        ChunkCompression,
        typer.Option(
            "--chunk-compression", help="Compress MCAP chunks: none, zstd or lz4 (MCAP bags only)."
        ),
    ] = ChunkCompression.NONE,
    chunk_compression_level: ChunkCompressionLevel = None,
    repeat_latched: RepeatLatched = True,
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
    matches --topics or --regex and no exclusion, also to topics that appear
    later, and writes each message with its receive time and its type's
    definition. ROS 2 bags stay readable if the recorder is killed (up to the
    last second or so). If the server goes away the recorder reconnects (and
    subscribes again) until it stops; with --duration it stops on time even then.
    """
    if compression not in ("cbor", "none"):
        fail("record", f"--compression must be cbor or none, not {compression}")
    from rwt_bag.jobs import record_remote  # noqa: PLC0415 - see record_options

    options = record_options(
        out,
        topic_selection(topics, regex, exclude_regex, exclude_topics),
        fmt,
        split_policy(max_bag_size, max_bag_duration, size_mb=split_size, duration_s=split_duration),
        compression=chunk_compression(chunk_compression_algorithm, chunk_compression_level),
        repeat_latched=repeat_latched,
    )

    tune_allocator(HEAP_KEEP_MIB * 1024 * 1024)  # as rwt serve does: images, clouds
    registry = TypeRegistry(dialect_for(dialect, (), fmt), interfaces or ())
    with one_line_errors("record", RECORD_ERRORS):
        anyio.run(
            lambda: record_remote(
                url,
                out,
                registry,
                record=options,
                compression=compression,
                duration=duration,
            )
        )
