"""Which ROS edition a server speaks, asked of the server itself.

Two questions, asked at once over one connection and bounded together (a
server that answers neither costs one timeout, not two):

1. ``/rosapi/get_ros_version`` (rosapi of rosbridge_suite 2.x and rwt): its
   ``version`` is 1 or 2.
2. When that service is absent (rosbridge_suite 0.11.x has none,
   docs/reference-behaviour.md REF §7.1), ``/rosapi/message_details`` of
   ``std_msgs/Header``: ROS 1's header starts with ``seq`` and its stamp is a
   ``time``; ROS 2's has neither. Its answer is used only when the first
   question's is not.

A server that answers neither is taken to be ROS 2, the default of rwt and of
rosbridge_suite's current branch, and the answer says so. So is a server that
breaks the runner's bounds (``bounds``): sends that do not go out, frames too
big or too deep; every send, wait and the close are bounded in time.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import anyio

from rwt_client.connectors import Connection, ConnectionClosedError, connect

from .bounds import MAX_FRAME_BYTES, SendTimeoutError, close_within, send_within
from .frames import auth_op, decode_frame
from .model import Dialect

if TYPE_CHECKING:
    import ssl

__all__ = ["detect_dialect"]


async def detect_dialect(
    url: str,
    ssl_context: ssl.SSLContext | None = None,
    timeout_s: float = 3.0,
    auth_secret: str | None = None,
    max_frame_bytes: int = MAX_FRAME_BYTES,
) -> tuple[Dialect, str]:
    """Ask the server at ``url`` which dialect it speaks.

    Args:
        url: the server (``ws://``, ``wss://``, ``tcp://``, ``tcp+tls://``).
        ssl_context: TLS settings, as for the run.
        timeout_s: bound of each question, seconds.
        auth_secret: the server's rosauth secret (D23), when it asks for one.
        max_frame_bytes: largest frame taken from the server, bytes.

    Returns:
        The dialect and how it was found (one line, printed by the CLI).
        Never raises for what the server does: an unreachable or silent
        server gives ROS 2, "assumed".
    """
    try:
        conn = await connect(
            url, timeout_s=2 * timeout_s, max_message_size=max_frame_bytes, ssl_context=ssl_context
        )
    except (ConnectionClosedError, TimeoutError):
        return Dialect.ROS2, "assumed (the server could not be reached)"
    try:
        if auth_secret is not None:
            host = urlsplit(url).hostname or ""
            await send_within(conn, json.dumps(auth_op(auth_secret, {}, host)), timeout_s)
        version, details = await _ask(conn, timeout_s)
        if isinstance(version, dict) and _tells_version(version):
            dialect = Dialect.ROS1 if version["version"] == 1 else Dialect.ROS2
            return dialect, f"/rosapi/get_ros_version says {version['version']}"
        names = _header_fields(details)
        if names is not None:
            dialect = Dialect.ROS1 if "seq" in names else Dialect.ROS2
            return dialect, f"std_msgs/Header has fields {', '.join(names)}"
        return Dialect.ROS2, "assumed (rosapi answered neither get_ros_version nor message_details)"
    except ConnectionClosedError as exc:
        return Dialect.ROS2, f"assumed (the server closed the connection: {exc.message})"
    except SendTimeoutError as exc:
        return Dialect.ROS2, f"assumed ({exc})"
    finally:
        await close_within(conn)


_VERSION = "/rosapi/get_ros_version"
_DETAILS = "/rosapi/message_details"


async def _ask(conn: Connection, timeout_s: float) -> tuple[object, object]:
    """Both questions' ``values`` (None: failed, or no answer in ``timeout_s``).

    Both calls go out at once; the wait ends when ``get_ros_version`` has told the
    dialect, when both are answered, or after ``timeout_s``.
    """
    questions: dict[str, tuple[str, dict[str, object]]] = {
        f"rwt_conformance_detect:{_VERSION}": (_VERSION, {}),
        f"rwt_conformance_detect:{_DETAILS}": (_DETAILS, {"type": "std_msgs/Header"}),
    }
    for call_id, (service, args) in questions.items():
        call = {"op": "call_service", "service": service, "args": args, "id": call_id}
        await send_within(conn, json.dumps(call), timeout_s)
    answers: dict[str, object] = {}
    with anyio.move_on_after(timeout_s):
        while len(answers) < len(questions) and not _tells_version(answers.get(_VERSION)):
            value = decode_frame(await conn.receive()).value
            if not isinstance(value, dict) or value.get("op") != "service_response":
                continue
            answer_id = value.get("id")
            if isinstance(answer_id, str) and answer_id in questions:
                service = questions[answer_id][0]
                answers[service] = value.get("values") if value.get("result") is True else None
    return answers.get(_VERSION), answers.get(_DETAILS)


def _tells_version(values: object) -> bool:
    """Whether a ``get_ros_version`` answer says 1 or 2."""
    return isinstance(values, dict) and values.get("version") in (1, 2)


def _header_fields(details: object) -> list[str] | None:
    """The field names of the first typedef of a ``message_details`` answer."""
    if not isinstance(details, dict):
        return None
    typedefs = details.get("typedefs")
    if not isinstance(typedefs, list) or not typedefs or not isinstance(typedefs[0], dict):
        return None
    names = typedefs[0].get("fieldnames")
    if not isinstance(names, list):
        return None
    # repr's escapes keep what the server wrote printable (lone surrogates, controls)
    return [name if isinstance(name, str) and name.isprintable() else repr(name) for name in names]
