"""The two ends of a rosbridge connection."""

from __future__ import annotations

from enum import StrEnum

__all__ = ["Role"]


class Role(StrEnum):
    """Which end of a rosbridge connection a session plays (as h11's ``our_role``).

    Both roles speak the same ops (``rwt_protocol.ops``): a ``Session`` is the
    server end, a ``ClientSession`` the client end; each has ``our_role``,
    ``receive_frame`` and ``frames_to_send``.
    """

    SERVER = "server"
    CLIENT = "client"
