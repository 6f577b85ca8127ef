"""The player's services, so a web page can pause, resume, seek and show progress.

Under ``/rwt/player/`` (docs/record-replay.md):

=================  ===============================  =====================================
service            type                             does
=================  ===============================  =====================================
``pause``          ``std_srvs/srv/Trigger``         stop publishing (``/clock`` stops)
``resume``         ``std_srvs/srv/Trigger``         go on from there
``seek``           ``rwt_msgs/srv/Seek``            go to ``offset`` seconds into the bag
``get_status``     ``rwt_msgs/srv/GetPlayerStatus`` paused, position, duration, rate
=================  ===============================  =====================================
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from rwt_graph.ratelog import EpisodeLog

from .errors import BagError

if TYPE_CHECKING:
    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalService

    from .player import Player

__all__ = ["PREFIX", "serve_controls"]

PREFIX = "/rwt/player"

Message = dict[str, object]

logger = logging.getLogger("rwt.bag")


def serve_controls(graph: Graph, player: Player, prefix: str = PREFIX) -> list[LocalService]:
    """Offer ``player``'s controls as services of ``graph``; close them to withdraw.

    A refused request (a seek to NaN, infinity or outside the bag) is answered
    with ``success: false`` and the reason, logged once per episode
    (``rwt_graph.ratelog.EpisodeLog``): a client calling in a loop cannot write
    the server's log at its own rate.

    Raises:
        GraphError: a service name is taken by another provider.
    """
    episodes = EpisodeLog(logger)

    def pause(request: Message) -> Message:
        player.pause()
        return {"success": True, "message": f"paused at {player.position_s:.3f} s"}

    def resume(request: Message) -> Message:
        player.resume()
        return {"success": True, "message": f"playing from {player.position_s:.3f} s"}

    def seek(request: Message) -> Message:
        offset = request["offset"]
        try:
            seconds = float(offset) if isinstance(offset, int | float) else math.nan
            player.seek(seconds, clamp=False)
        except BagError as exc:
            episodes.log(logging.WARNING, "player_seek", "event=player_seek_refused reason=%s", exc)
            return {"success": False, "message": f"seek: {exc}"}
        return {"success": True, "message": f"at {player.position_s:.3f} s"}

    def status(request: Message) -> Message:
        return {
            "paused": player.paused,
            "position": player.position_s,
            "duration": player.duration_s,
            "rate": player.rate,
            "published": player.stats.messages,
        }

    node = "/rwt_player"
    return [
        graph.create_service(f"{prefix}/pause", "std_srvs/srv/Trigger", pause, node=node),
        graph.create_service(f"{prefix}/resume", "std_srvs/srv/Trigger", resume, node=node),
        graph.create_service(f"{prefix}/seek", "rwt_msgs/srv/Seek", seek, node=node),
        graph.create_service(
            f"{prefix}/get_status", "rwt_msgs/srv/GetPlayerStatus", status, node=node
        ),
    ]
