"""The robot's MCP App: a camera and a hold-to-drive pad a host renders beside the chat.

MCP Apps (the ``io.modelcontextprotocol/ui`` extension, SEP-1865): a tool names a
``ui://`` resource in its ``_meta.ui.resourceUri``; a host that renders apps reads
that resource (HTML, ``text/html;profile=mcp-app``), shows it in a sandboxed frame,
hands it the tool's result, and carries the frame's ``tools/call`` requests to this
server over the agent's own MCP connection. So the app drives the robot under the
connection's authentication, access rules, read-only mode and caps, as the agent
would (docs/mcp.md, "The robot app").

``robot_app`` (the tool) answers the app's settings (``RobotApp``): the camera
topic, where its video is (``POST /webrtc?video=TOPIC`` of ``rwt serve --webrtc``
on the server's port, as a WHEP player asks; ``/stream?topic=TOPIC&type=mjpeg`` of
``rwt serve --video`` when there is one, the fallback), a video token when the
server wants one, and whether the pad may drive (not in read-only mode, and
``cmd_vel`` allowed by ``--topics-pub-glob``). The pad publishes
``geometry_msgs/msg/Twist`` on ``cmd_vel`` through the ``publish`` tool
``TELEOP_RATE_HZ`` times a second only while it is held, and one zero Twist when
it is let go, the frame hides or the host tears the app down: a dead-man switch.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources
from typing import Any
from urllib.parse import quote

from pydantic import BaseModel

__all__ = [
    "APP_MIME",
    "APP_URI",
    "TELEOP_RATE_HZ",
    "AppSite",
    "RobotApp",
    "app_html",
    "app_resource_meta",
    "app_settings",
]

APP_URI = "ui://rwt/robot"
"""The app's resource (MCP Apps: the ``ui://`` scheme)."""
APP_MIME = "text/html;profile=mcp-app"
"""The MIME type of an MCP App's HTML (MCP Apps: the ``mcp-app`` profile)."""
TELEOP_RATE_HZ = 5.0
"""Twists a second the held pad publishes: within ``publish``'s cap of
``guard.TOOL_CALLS_PER_S`` (10) calls a second, with room for the agent's own."""


@dataclass(frozen=True, slots=True)
class AppSite:
    """Where the app finds the server's video, as the agent's host reaches the server.

    Attributes:
        base: ``http(s)://HOST:PORT`` of the rosbridge port (WebRTC offers go to
            ``/webrtc`` there); None: not known.
        webrtc: whether that port answers WebRTC offers (``--webrtc``); None: not
            known (``rwt mcp URL``: the app tries, then falls back).
        video: ``http(s)://HOST:PORT`` of the video server (``--video``); None: none.
        auth: whether the server wants a video token (``--auth-secret-file``); None:
            not known (the app's tool then asks for one, and goes on without).
    """

    base: str | None = None
    webrtc: bool | None = None
    video: str | None = None
    auth: bool | None = None


class RobotApp(BaseModel):
    """``robot_app``'s answer: the app's settings (what the app reads from the tool result)."""

    camera: str | None
    """The image topic shown; None: no camera."""
    webrtc_url: str | None
    """Where the app posts its WebRTC offer (WHEP style) for the camera's video track."""
    mjpeg_url: str | None
    """The camera as MJPEG (an ``<img>``), where the video server runs."""
    token: str | None
    """A video token (``/rwt/video_token``, 60 s) for both, where the server wants one."""
    cmd_vel: str
    """The topic the pad drives (``geometry_msgs/msg/Twist``)."""
    teleop: bool
    """Whether the pad may drive; else ``teleop_refused`` says why."""
    teleop_refused: str | None = None
    max_linear: float
    """The pad's top speed forward and back, m/s."""
    max_angular: float
    """The pad's top turn rate, rad/s."""
    rate_hz: float = TELEOP_RATE_HZ
    """Twists a second while the pad is held."""


def app_settings(
    site: AppSite,
    camera: str | None,
    token: str | None,
    cmd_vel: str,
    refused: str | None,
    max_linear: float,
    max_angular: float,
) -> RobotApp:
    """The app's settings for ``camera`` (None: none) at ``site``."""
    webrtc = mjpeg = None
    if camera:
        if site.base is not None and site.webrtc is not False:
            webrtc = f"{site.base}/webrtc?video={quote(camera, safe='/')}"
        if site.video is not None:
            mjpeg = f"{site.video}/stream?topic={quote(camera, safe='/')}&type=mjpeg"
            if token is not None:
                mjpeg += f"&token={quote(token, safe='')}"
    return RobotApp(
        camera=camera or None,
        webrtc_url=webrtc,
        mjpeg_url=mjpeg,
        token=token,
        cmd_vel=cmd_vel,
        teleop=refused is None,
        teleop_refused=refused,
        max_linear=max_linear,
        max_angular=max_angular,
    )


@functools.cache
def app_html() -> str:
    """The app's HTML: one self-contained page (its script and style inline)."""
    return resources.files(__package__).joinpath("static/robot_app.html").read_text("utf-8")


def app_resource_meta(site: AppSite) -> dict[str, Any]:
    """The resource's ``_meta.ui``: the origins its frame may reach (MCP Apps' CSP).

    ``connectDomains`` for the WebRTC offer (a ``fetch``), ``resourceDomains`` for
    the MJPEG ``<img>``; a host lets the frame reach nothing else.
    """
    connect = [site.base] if site.base is not None else []
    images = [site.video] if site.video is not None else []
    return {"ui": {"csp": {"connectDomains": connect, "resourceDomains": images}}}
