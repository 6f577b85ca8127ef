"""The depth-cloud encoder as a participant of the graph (depthcloud_encoder's node).

It subscribes to a depth image topic (and optionally a colour one) and publishes
one ``sensor_msgs/Image`` per depth frame on ``/depthcloud_encoded``, which the
video server streams to ros3djs's ``DepthCloud`` like any other image topic.

Encoding a frame takes 16 ms of CPU at 640x480 and 0.65 s at 3840x2160, and
whoever publishes on the depth topic chooses both size and rate. So while a
server runs the graph (its spawner), frames are encoded in an image thread
(``threads``, shared with every front end's image work), never on the event
loop, one at a time: a frame paired while another is encoded waits, and a newer
one replaces it (the newest goes out, as the video server's streams do).
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Mapping
from typing import TYPE_CHECKING

from ..ratelog import EpisodeLog
from ..types.convert import header_stamp
from .depthcloud import encode_depthcloud
from .images import ImageError, array_to_image, depth_to_metres, image_to_display
from .threads import in_image_thread

if TYPE_CHECKING:
    from ..graph import Graph
    from ..local import LocalPublisher, LocalSubscription

__all__ = ["DEFAULT_TOPIC", "DepthCloudEncoder"]

logger = logging.getLogger("rwt.depthcloud")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

#: Where depthcloud_encoder publishes (``depthcloud_encoded`` in its namespace).
DEFAULT_TOPIC = "/depthcloud_encoded"
IMAGE_TYPE = "sensor_msgs/msg/Image"
_KEPT_COLOUR_FRAMES = 10  # depthcloud_encoder's synchroniser queue size

Message = Mapping[str, object]


class DepthCloudEncoder:
    """Encodes depth (+ colour) frames from the graph and publishes the tiled image.

    Pairing: a depth frame goes out at once with the colour frame of the same
    header stamp when that has arrived; otherwise it waits until a colour frame
    with its stamp, a newer colour frame or a newer depth frame arrives, and
    then goes out with the colour frame nearest in time (depthcloud_encoder uses
    an approximate-time synchroniser). Without a colour topic every depth
    frame goes out at once. Frames that cannot be encoded are logged and skipped.

    Args:
        graph: the graph to subscribe and publish on.
        depth_topic: ``32FC1`` (metres) or ``16UC1`` (millimetres) depth images.
        rgb_topic: colour images of the same size, or None.
        topic: output topic.
        max_depth_per_tile: d in metres (near tile 0..d, far tile d..2d).
        tile_size: tile side in pixels; the output is twice that square.
        node: the node rosapi lists for the encoder.

    Raises:
        GraphError: a topic exists with another type.
        ImageError: a bad d or tile size.
    """

    def __init__(
        self,
        graph: Graph,
        depth_topic: str,
        rgb_topic: str | None = None,
        *,
        topic: str = DEFAULT_TOPIC,
        max_depth_per_tile: float = 1.0,
        tile_size: int = 512,
        node: str = "/depthcloud_encoder",
    ) -> None:
        if max_depth_per_tile <= 0 or tile_size <= 0:
            raise ImageError("max_depth_per_tile and tile_size must be positive")
        self.max_depth_per_tile = max_depth_per_tile
        self.tile_size = tile_size
        self._colours: deque[Message] = deque(maxlen=_KEPT_COLOUR_FRAMES)
        self._pending: Message | None = None
        self._graph = graph
        self._next: tuple[Message, Message | None] | None = None  # waiting for the thread
        self._encoding = False
        self._last_error = ""
        self._publisher: LocalPublisher = graph.create_publisher(
            topic, IMAGE_TYPE, node=node, reserved=True
        )
        self._subscriptions: list[LocalSubscription] = []
        try:
            self._subscriptions.append(
                graph.create_subscription(depth_topic, self._on_depth, IMAGE_TYPE, node=node)
            )
            self._with_colour = rgb_topic is not None
            if rgb_topic is not None:
                self._subscriptions.append(
                    graph.create_subscription(rgb_topic, self._on_colour, IMAGE_TYPE, node=node)
                )
        except BaseException:
            self.close()
            raise

    def encode(self, depth_msg: Message, colour_msg: Message | None = None) -> dict[str, object]:
        """The encoded Image message for one frame (the depth message's header).

        Raises:
            ImageError: a depth image that is not 32FC1/16UC1, an unreadable
                colour image, or sizes that differ.
        """
        depth = depth_to_metres(depth_msg)
        colour = None
        if colour_msg is not None:
            colour = image_to_display(colour_msg)
            if colour.shape[:2] != depth.shape:
                raise ImageError(
                    f"colour image {colour.shape[1]}x{colour.shape[0]} does not match "
                    f"depth image {depth.shape[1]}x{depth.shape[0]}"
                )
        tiles = encode_depthcloud(
            depth, colour, max_depth_per_tile=self.max_depth_per_tile, tile_size=self.tile_size
        )
        header = depth_msg.get("header")
        return array_to_image(tiles, "bgr8", header=header if isinstance(header, Mapping) else None)

    def close(self) -> None:
        """Stop encoding; the output topic goes when nobody else uses it."""
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions.clear()
        self._publisher.close()

    # ---- pairing -----------------------------------------------------------------

    def _on_depth(self, msg: Message) -> None:
        if not self._with_colour:
            self._publish(msg, None)
            return
        if self._pending is not None:
            self._publish(self._pending, self._nearest_colour(self._pending))
        self._pending = msg
        self._try_exact()

    def _on_colour(self, msg: Message) -> None:
        self._colours.append(msg)
        pending = self._pending
        if pending is None:
            return
        if _stamp_ns(msg) >= _stamp_ns(pending):  # no colour frame with its stamp is coming
            self._pending = None
            self._publish(pending, self._nearest_colour(pending))

    def _try_exact(self) -> None:
        pending = self._pending
        if pending is not None and self._colours:
            nearest = self._nearest_colour(pending)
            if nearest is not None and _stamp_ns(nearest) >= _stamp_ns(pending):
                self._pending = None
                self._publish(pending, nearest)

    def _nearest_colour(self, depth_msg: Message) -> Message | None:
        stamp = _stamp_ns(depth_msg)
        return min(self._colours, key=lambda c: abs(_stamp_ns(c) - stamp), default=None)

    def _publish(self, depth_msg: Message, colour_msg: Message | None) -> None:
        """Encode and publish a pair: in an image thread while a server runs the graph."""
        spawner = self._graph.port.spawner
        if spawner is None:  # no event loop (a test, a script): at once
            self._publish_encoded(self._encoded(depth_msg, colour_msg))
            return
        self._next = (depth_msg, colour_msg)  # a newer pair replaces one still waiting
        if not self._encoding:
            self._encoding = True
            spawner(self._encode_waiting)

    async def _encode_waiting(self) -> None:
        try:
            while self._next is not None:
                (depth_msg, colour_msg), self._next = self._next, None
                encoded = await in_image_thread(self._encoded, depth_msg, colour_msg)
                if self._subscriptions:  # not closed meanwhile
                    self._publish_encoded(encoded)
        finally:
            self._encoding = False

    def _encoded(self, depth_msg: Message, colour_msg: Message | None) -> dict[str, object] | None:
        """The encoded frame, or None (logged) for a frame that cannot be encoded."""
        try:
            return self.encode(depth_msg, colour_msg)
        except ImageError as exc:
            if str(exc) != self._last_error:  # once per cause, not 30 times a second
                _episodes.log(
                    logging.WARNING, "depthcloud_skipped", "depth cloud frame skipped: %s", exc
                )
                self._last_error = str(exc)
            return None

    def _publish_encoded(self, encoded: dict[str, object] | None) -> None:
        if encoded is not None:
            self._publisher.publish(encoded)


def _stamp_ns(msg: Message) -> int:
    """The header stamp in nanoseconds (either dialect's time fields); 0 without one."""
    sec, nsec = header_stamp(msg) or (0, 0)
    return sec * 1_000_000_000 + nsec
