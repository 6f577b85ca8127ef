"""The Zenoh link: servers sharing one graph over rmw_zenoh's wire (docs/scaling.md).

Needs the ``zenoh`` extra (``pip install "rwt-rosbridge[zenoh]"``), loaded with the first
of these names used.

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_zenoh.config import ZenohOptions
    from rwt_zenoh.link import ZenohLink, open_zenoh_link
    from rwt_zenoh.wire import RmwCompat, WireError

__all__ = [
    "RmwCompat",
    "WireError",
    "ZenohLink",
    "ZenohOptions",
    "open_zenoh_link",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
