"""How an rwt process joins a Zenoh network: the options of ``rwt serve --zenoh``.

The session follows rmw_zenoh's defaults where they matter (docs/scaling.md):
multicast scouting is off, so peers find each other through the endpoints given
(``--zenoh-connect``/``--zenoh-listen``) or a router; timestamping is on, which
the transient-local (latched) publisher cache needs. A JSON5 config file, when
given, is read first and these options override it.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from ipaddress import ip_address
from typing import TYPE_CHECKING

from rwt_protocol.errors import ConfigError

from .limits import MAX_OUTBOX_BYTES, MAX_QUEUED_BYTES, MAX_REMOTE_ENTITIES
from .wire import RmwCompat

if TYPE_CHECKING:
    from pathlib import Path

    import zenoh

__all__ = [
    "Mode",
    "ZenohOptions",
    "default_domain_id",
    "endpoint_host",
    "is_loopback_endpoint",
    "make_config",
]

Mode = str
"""``peer``, ``client`` or ``router`` (Zenoh's ``mode``)."""

MODES = ("peer", "client", "router")

_HEADROOM = 64 * 1024  # a message's key, attachment and framing besides its payload

LOOPBACK_LISTEN = "tcp/127.0.0.1:0"
"""Where a peer listens when told nothing: this machine only, as rmw_zenoh's default
session config does (another machine connects when ``--zenoh-listen`` says so)."""


def default_domain_id() -> int:
    """``ROS_DOMAIN_ID`` from the environment, 0 when unset or not a number (as ROS 2 does)."""
    try:
        return int(os.environ.get("ROS_DOMAIN_ID", "0"))
    except ValueError:
        return 0


@dataclass(frozen=True)
class ZenohOptions:
    """What ``--zenoh*`` and ``--domain-id`` say.

    Attributes:
        mode: ``peer`` (default), ``client`` (through a router) or ``router``.
        connect: endpoints to connect to, e.g. ``tcp/127.0.0.1:7447``.
        listen: endpoints to listen on; a peer given none listens on
            ``tcp/127.0.0.1:0`` (``LOOPBACK_LISTEN``).
        config_file: a Zenoh JSON5 config read first; the options above override it.
        domain_id: the ROS domain, the first part of every key.
        multicast: multicast scouting (off, as in rmw_zenoh; discovery goes
            through endpoints or a router).
        rmw_compat: which rmw_zenoh's token defaults to speak (``--zenoh-rmw-compat``;
            docs/zenoh.md, "Which rmw_zenoh").
        queue_bytes: bytes of remote samples waiting for the event loop at most
            (``--zenoh-queue-bytes``); also the largest message Zenoh accepts.
        outbox_bytes: bytes of local samples waiting for their put at most
            (``--zenoh-outbox-bytes``); past half of it the publishing connection
            is held back (``outbox.Outbox``).
        max_entities: remote entities (liveliness tokens) mirrored at once
            (``--zenoh-max-entities``).
    """

    mode: Mode = "peer"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_file: Path | None = None
    domain_id: int = field(default_factory=default_domain_id)
    multicast: bool = False
    rmw_compat: RmwCompat = RmwCompat.CURRENT
    queue_bytes: int = MAX_QUEUED_BYTES
    outbox_bytes: int = MAX_OUTBOX_BYTES
    max_entities: int = MAX_REMOTE_ENTITIES


def make_config(options: ZenohOptions) -> zenoh.Config:
    """The Zenoh config of ``options``.

    Raises:
        ConfigError: an unknown mode, or a config file Zenoh cannot read (the text
            names the file).
    """
    import zenoh  # noqa: PLC0415 - the zenoh extra loads only with --zenoh

    if options.mode not in MODES:
        raise ConfigError(f"zenoh mode {options.mode!r}: expected one of {', '.join(MODES)}")
    if options.config_file is not None:
        try:
            config = zenoh.Config.from_file(str(options.config_file))
        except Exception as exc:  # zenoh raises ZError with the parser's text
            raise ConfigError(f"cannot read zenoh config {options.config_file}: {exc}") from None
    else:
        config = zenoh.Config()
    config.insert_json5("mode", json.dumps(options.mode))
    config.insert_json5("scouting/multicast/enabled", json.dumps(options.multicast))
    config.insert_json5("timestamping/enabled", "true")
    # a sample larger than the queue could never wait in it: Zenoh need not reassemble
    # one (its default accepts 1 GiB messages from any peer)
    config.insert_json5(
        "transport/link/rx/max_message_size", json.dumps(options.queue_bytes + _HEADROOM)
    )
    if options.connect:
        config.insert_json5("connect/endpoints", json.dumps(list(options.connect)))
    listen = list(options.listen)
    if not listen and options.config_file is None and options.mode == "peer":
        listen = [LOOPBACK_LISTEN]  # Zenoh's own default listens on every interface
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(listen))
    return config


def endpoint_host(endpoint: str) -> str:
    """The host of a Zenoh endpoint: ``tcp/127.0.0.1:7447`` -> ``127.0.0.1``.

    Raises:
        ConfigError: not ``<protocol>/<host>:<port>``.
    """
    _, slash, address = endpoint.partition("/")
    host, colon, _ = address.split("#")[0].rpartition(":")
    if not slash or not colon or not host:
        raise ConfigError(f"zenoh endpoint {endpoint!r}: expected <protocol>/<host>:<port>")
    return host.strip("[]")


def is_loopback_endpoint(endpoint: str) -> bool:
    """Whether an endpoint stays on this machine (127.0.0.0/8, ::1 or ``localhost``)."""
    try:
        host = endpoint_host(endpoint)
    except ValueError:
        return False
    if host == "localhost":
        return True
    try:
        return ip_address(host).is_loopback
    except ValueError:
        return False
