"""The HTML pages of the video server: the topic list and the stream viewer.

Laid out as web_video_server's: image topics grouped under the camera whose
``camera_info`` topic shares their prefix, each with links to its viewer page,
its stream and a snapshot; the viewer page holds an ``<img>`` (mjpeg, png,
ros_compressed) or a ``<video>`` (vp8, vp9, h264) pointing at ``/stream``.

The ``<video>`` is muted and started by script: Chromium's default autoplay
policy lets a muted video play without a user's gesture, but a headless or
background tab may still hold ``autoplay`` back until the page calls ``play()``;
when even that is refused, a Play button appears (docs/video.md).
"""

from __future__ import annotations

from dataclasses import fields
from html import escape
from urllib.parse import urlencode

from .params import StreamParams, StreamType

__all__ = ["stream_viewer_page", "topic_list_page"]


def topic_list_page(topics: list[tuple[str, str]], token: str | None = None) -> str:
    """The ``/`` page for the graph's ``(topic, type)`` pairs; links carry ``token`` if given."""
    images = [name for name, kind in topics if kind.replace("/msg/", "/") == "sensor_msgs/Image"]
    cameras = [
        name.removesuffix("camera_info")
        for name, kind in topics
        if kind.replace("/msg/", "/") == "sensor_msgs/CameraInfo" and name.endswith("/camera_info")
    ]
    lines = [
        "<html><head><title>ROS Image Topic List</title></head>",
        "<body><h1>Available ROS Image Topics:</h1>",
        "<ul>",
    ]
    for base in cameras:
        mine = [name for name in images if name.startswith(base)]
        images = [name for name in images if name not in mine]
        items = "".join(_topic_item(name, name[len(base) :], token) for name in mine)
        lines.append(f"<li>{escape(base)}<ul>{items}</ul></li>")
    lines.append("</ul><ul>")
    lines.extend(_topic_item(name, name, token) for name in images)
    lines.append("</ul></body></html>")
    return "\n".join(lines)


def stream_viewer_page(params: StreamParams, token: str | None = None) -> str:
    """The ``/stream_viewer`` page: the stream in an element a browser plays.

    ``token``: the video token the stream URL carries (docs/video.md), if any.
    """
    source = escape(f"/stream?{_query(params, token)}")
    if params.type.is_video:
        element = (
            f'<video src="{source}" id="stream" autoplay muted playsinline></video>'
            '<p><button id="play" type="button" hidden>&#9654; Play</button></p>'
            f"<script>{_START_VIDEO}</script>"
        )
    else:
        element = f'<img src="{source}"></img>'
    title = escape(params.topic)
    head = f'<title>{title}</title><link rel="icon" href="data:,">'  # no /favicon.ico 404
    return f"<html><head>{head}</head><body><h1>{title}</h1>{element}</body></html>"


_START_VIDEO = (
    "const video = document.getElementById('stream');"
    "const button = document.getElementById('play');"
    "video.muted = true;"  # the property decides the autoplay policy, not the attribute
    "const start = () => video.play().then(() => { button.hidden = true; },"
    " () => { button.hidden = false; });"
    "button.addEventListener('click', start);"
    "start();"
)


def _topic_item(topic: str, label: str, token: str | None) -> str:
    query = urlencode({"topic": topic} | ({} if token is None else {"token": token}))
    return (
        f'<li><a href="/stream_viewer?{escape(query)}">{escape(label)}</a> '
        f'(<a href="/stream?{escape(query)}">Stream</a>) '
        f'(<a href="/snapshot?{escape(query)}">Snapshot</a>)</li>'
    )


def _query(params: StreamParams, token: str | None = None) -> str:
    """The query that asks for ``params`` again (defaults left out), with ``token`` if given."""
    default = StreamParams(topic=params.topic, type=params.type)
    pairs: list[tuple[str, str]] = [("topic", params.topic), ("type", params.type.value)]
    for field in fields(StreamParams):
        value = getattr(params, field.name)
        if field.name in ("topic", "type") or value == getattr(default, field.name):
            continue
        if field.name == "invert":
            pairs.append(("invert", ""))
        elif field.name != "quality" or params.type in (StreamType.MJPEG, StreamType.PNG):
            pairs.append((field.name, str(value)))
    if token is not None:
        pairs.append(("token", token))
    return urlencode(pairs)
