"""The HTTP video server of ``rwt serve --video`` (web_video_server compatible).

``serve_video(graph, VideoConfig(...))`` runs it on any graph; see ``server``.
"""

from __future__ import annotations

from .params import StreamParams, StreamType
from .server import VideoConfig, serve_video

__all__ = ["StreamParams", "StreamType", "VideoConfig", "serve_video"]
