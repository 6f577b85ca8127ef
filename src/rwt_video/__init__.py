"""The HTTP video server of ``rwt serve --video`` (web_video_server compatible).

``serve_video(graph, VideoConfig(...))`` runs it on any graph; see ``server``.
With ``VideoConfig(tokens=VideoTokens())`` and ``install_token_service`` it serves
only requests carrying a token that an authenticated connection got (``tokens``).
Its shared streams (``hub``) also feed WebRTC's video tracks, with the RTP
encoders of ``rtp`` (``rwt serve --webrtc``, docs/webrtc.md).
"""

from __future__ import annotations

from .params import StreamParams, StreamType
from .server import VideoConfig, serve_video
from .tokens import VideoTokens, install_token_service

__all__ = [
    "StreamParams",
    "StreamType",
    "VideoConfig",
    "VideoTokens",
    "install_token_service",
    "serve_video",
]
