"""The TF republisher with the event loop's sleep: ``install_tf_republisher(graph)``.

The rest of ``rwt_graph.tf`` holds the buffer and the republishing logic and knows
no event loop; this module passes it ``anyio.sleep`` (a timer, no I/O).
``GraphServer`` calls it unless ``ServerConfig.tf`` is false (``rwt serve --no-tf``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import anyio

from .install import TF_NODE, TFRepublisher
from .install import install_tf_republisher as _install

if TYPE_CHECKING:
    from rwt_graph.graph import Graph

__all__ = ["install_tf_republisher"]


def install_tf_republisher(graph: Graph, *, node: str = TF_NODE) -> TFRepublisher:
    """Give ``graph`` a TF buffer, the ``/tf2_web_republisher`` action and ``/republish_tfs``.

    The ticking runs in the event loop of the server that serves ``graph``
    (``GraphCore.serving``); lookups from Python work at once:
    ``install_tf_republisher(graph).buffer.lookup("map", "gripper")``.

    Raises:
        GraphError: ``/tf`` or ``/tf_static`` is in use with another type.
    """
    return _install(graph, anyio.sleep, node=node)
