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

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalService

    from .player import Player

__all__ = ["PREFIX", "serve_controls"]

PREFIX = "/rwt/player"

Message = dict[str, object]


def serve_controls(graph: Graph, player: Player, prefix: str = PREFIX) -> list[LocalService]:
    """Offer ``player``'s controls as services of ``graph``; close them to withdraw.

    Raises:
        GraphError: a service name is taken by another provider.
    """

    def pause(request: Message) -> Message:
        player.pause()
        return {"success": True, "message": f"paused at {player.position_s:.3f} s"}

    def resume(request: Message) -> Message:
        player.resume()
        return {"success": True, "message": f"playing from {player.position_s:.3f} s"}

    def seek(request: Message) -> Message:
        offset = float(request["offset"])  # type: ignore[arg-type]  # float64 by its type
        player.seek(offset)
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
