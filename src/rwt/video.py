"""Image topics over HTTP with web_video_server's URLs (docs/video.md).

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_video import StreamType, VideoConfig, VideoTokens, install_token_service, serve_video

__all__ = [
    "StreamType",
    "VideoConfig",
    "VideoTokens",
    "install_token_service",
    "serve_video",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
