"""``rwt serve --zenoh`` and ``rwt router``: the command line's side of the Zenoh link.

The ``zenoh`` extra loads only when these are used, so a plain ``rwt serve``
neither needs nor imports it (docs/scaling.md).
"""

from __future__ import annotations

import contextlib
import importlib.util
import signal
from typing import TYPE_CHECKING

import anyio
import typer

from rwt_protocol.distribution import install_hint
from rwt_protocol.errors import ConfigError
from rwt_transports.process.gcfreeze import freeze_startup_objects

if TYPE_CHECKING:
    from collections.abc import AsyncIterator
    from pathlib import Path

    from rwt_graph.graph import Graph
    from rwt_zenoh.config import ZenohOptions

__all__ = ["ZENOH_EXTRA", "linked", "require_zenoh", "run_router", "zenoh_options"]

ZENOH_EXTRA = install_hint("zenoh")


def require_zenoh(option: str) -> None:
    """Check the extra is installed.

    Raises:
        ConfigError: it is not; the text says how to install it.
    """
    if importlib.util.find_spec("zenoh") is None or importlib.util.find_spec("xxhash") is None:
        raise ConfigError(f"{option} needs Eclipse Zenoh: {ZENOH_EXTRA}")


def zenoh_options(
    *,
    mode: str,
    connect: list[str] | None,
    listen: list[str] | None,
    config_file: Path | None,
    domain_id: int | None,
    rmw_compat: str = "current",
) -> ZenohOptions:
    """The link's options from the command line (``domain_id`` None: ``ROS_DOMAIN_ID`` or 0).

    Raises:
        ConfigError: the extra is missing.
    """
    require_zenoh("--zenoh")
    from rwt_zenoh.config import ZenohOptions, default_domain_id  # noqa: PLC0415
    from rwt_zenoh.wire import RmwCompat  # noqa: PLC0415

    return ZenohOptions(
        mode=mode,
        connect=tuple(connect or ()),
        listen=tuple(listen or ()),
        config_file=config_file,
        domain_id=default_domain_id() if domain_id is None else domain_id,
        rmw_compat=RmwCompat(rmw_compat),
    )


@contextlib.asynccontextmanager
async def linked(graph: Graph, options: ZenohOptions | None) -> AsyncIterator[None]:
    """Link ``graph`` to Zenoh while the block runs (nothing when ``options`` is None).

    Raises:
        ConfigError: Zenoh cannot start (a bad config, an endpoint in use...): one line.
    """
    if options is None:
        yield
        return
    import zenoh  # noqa: PLC0415
    from rwt_zenoh.link import open_zenoh_link  # noqa: PLC0415

    try:
        async with open_zenoh_link(graph, options):
            # the type store, numpy and Zenoh came after the start-up freeze: every full
            # collection walked them again (benchmarks/JOURNAL.md, "Workers' CPU per delivery")
            freeze_startup_objects()
            yield
    except zenoh.ZError as exc:  # opening or closing the session
        raise ConfigError(f"zenoh: {exc}") from None


def run_router(listen: list[str], config_file: Path | None) -> None:
    """Run a Zenoh router in this process until SIGINT or SIGTERM.

    Prints ``router listening on ENDPOINT`` per endpoint and ``router <zid>``.

    Raises:
        ConfigError: the extra is missing, or Zenoh cannot start.
    """
    require_zenoh("rwt router")
    import zenoh  # noqa: PLC0415
    from rwt_zenoh.config import ZenohOptions, make_config  # noqa: PLC0415

    options = ZenohOptions(mode="router", listen=tuple(listen), config_file=config_file)
    try:
        session = zenoh.open(make_config(options))
    except zenoh.ZError as exc:
        raise ConfigError(f"zenoh: {exc}") from None
    try:
        for endpoint in listen:
            typer.echo(f"router listening on {endpoint}")
        typer.echo(f"router {session.info.zid()}")
        anyio.run(_until_signal)
    finally:
        session.close()  # type: ignore[no-untyped-call]


async def _until_signal() -> None:
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            typer.echo("router stopping", err=True)
            return
