"""The errors a program rarely catches by name (docs/api.md).

Every error rwt raises on purpose is an ``rwt.RwtError``; ``rwt`` holds the root,
its first branches and the errors most programs catch (``rwt.FieldError``,
``rwt.ServiceCallError``, ``rwt.ListenError``...). The errors of one feature live
in its namespace (``rwt.tf.TFError``, ``rwt.bag.BagError``,
``rwt.types.UnknownTypeError``); the rest of the tree is here: a peer's protocol
errors and caps, the misuse of an op model, a service or action that does not
exist, and the parameter store's errors.
docs/api.md lists each error's place; the tree is drawn in rwt_protocol/errors.py.

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_graph.parameters.store import (
        ParameterError,
        ParameterNotSetError,
        ParameterStoreFullError,
    )
    from rwt_protocol.errors import (
        LimitError,
        LocalProtocolError,
        RemoteProtocolError,
        UnknownNameError,
    )
    from rwt_protocol.framing.messages import MessageTooBigError

__all__ = [
    "LimitError",
    "LocalProtocolError",
    "MessageTooBigError",
    "ParameterError",
    "ParameterNotSetError",
    "ParameterStoreFullError",
    "RemoteProtocolError",
    "UnknownNameError",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
