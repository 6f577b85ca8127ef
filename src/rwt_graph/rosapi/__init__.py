"""rosapi, built in: graph introspection and parameters as ``/rosapi/*`` services (REF §7.1).

``install_rosapi(graph)`` registers them as in-process services of node
``/rosapi``; ``GraphServer`` does so for every server. Listings answer for
the calling client through a ``Visibility`` (the hook for access rules).
In ROS 2 it also makes each node with parameters answer its own parameter
services (``nodeparams``), as ROS 2 tools expect.
"""

from __future__ import annotations

from .install import ROSAPI_NODE, Rosapi, install_rosapi, rosapi_service_names
from .typedefs import TypeDef, typedefs
from .visibility import EVERYTHING, NameFilter, Visibility, VisibilityFor

__all__ = [
    "EVERYTHING",
    "ROSAPI_NODE",
    "NameFilter",
    "Rosapi",
    "TypeDef",
    "Visibility",
    "VisibilityFor",
    "install_rosapi",
    "rosapi_service_names",
    "typedefs",
]
