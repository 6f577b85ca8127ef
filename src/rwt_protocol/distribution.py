"""The name rwt installs under, and the install hints that name its extras.

The import packages are ``rwt`` and ``rwt_*``; the distribution, what ``pip``
installs, is ``rwt-rosbridge``. The PyPI name ``rwt`` belongs to an unrelated
project: a hint naming it would install someone else's package (and with
``-U`` replace this one). Every hint and install line says ``DISTRIBUTION``;
the docs tests refuse one that names another project.
"""

from __future__ import annotations

from typing import Final

__all__ = ["DISTRIBUTION", "install_hint"]

DISTRIBUTION: Final = "rwt-rosbridge"
"""The distribution's name on PyPI (``pyproject.toml``'s ``project.name``)."""


def install_hint(extra: str | None = None) -> str:
    """The command that installs rwt with ``extra``: ``pip install "rwt-rosbridge[ros2]"``.

    Args:
        extra: an optional dependency group of ``pyproject.toml`` (``server``,
            ``ros2``, ``zenoh``...), or None for the core alone.
    """
    return f'pip install "{DISTRIBUTION}[{extra}]"' if extra else f"pip install {DISTRIBUTION}"
