"""Image work off the event loop: the threads every front end's image work shares.

Decoding, converting, scaling and encoding images takes milliseconds to seconds
of CPU for one frame; done on the event loop it stalls every client of the
process. So every front end runs it in a worker thread (Pillow, numpy and the
codecs release the GIL while they work), and all of them together take at most
``IMAGE_THREADS`` threads at once, per event loop: the video server's and the
WebRTC tracks' encoders (``rwt_video.hub``), the MCP tools' images
(``rwt_mcp.render``). A piece of work waits for a thread's turn, so many streams
or many agents cannot take more of the CPU than that, and the event loop keeps
its share (D42; docs/limits.md, "Images the server decodes").
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, TypeVar

import anyio
import anyio.to_thread
from anyio.lowlevel import RunVar

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["IMAGE_THREADS", "image_threads", "in_image_thread"]

T = TypeVar("T")

#: Image work at once, over every front end of one event loop: half the CPUs, at
#: least one. Each thread competes with the event loop for the CPU; 16 video streams
#: of a 4K camera, each encoding in its own thread, took the event loop's turn away
#: from the rosbridge clients (docs/video.md).
IMAGE_THREADS = max(1, (os.cpu_count() or 1) // 2)

_LIMITER: RunVar[anyio.CapacityLimiter] = RunVar("rwt_image_threads")


def image_threads() -> anyio.CapacityLimiter:
    """The image threads of the running event loop (``IMAGE_THREADS`` of them), made once."""
    try:
        return _LIMITER.get()
    except LookupError:
        limiter = anyio.CapacityLimiter(IMAGE_THREADS)
        _LIMITER.set(limiter)
        return limiter


async def in_image_thread(function: Callable[..., T], *args: object) -> T:
    """``function(*args)`` in an image thread, once one is free; its result or its exception.

    Not cancellable once started (a thread cannot be stopped): the caller waits
    for the work it asked for, which the bounds of the work (``compressed``,
    the message size) keep short.
    """
    return await anyio.to_thread.run_sync(function, *args, limiter=image_threads())
