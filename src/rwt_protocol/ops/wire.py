"""msgspec twins of the op models, generated from them: the decoders of the hot paths.

pydantic validates every op with field paths in its errors (D1); for the op
that dominates traffic, ``publish``, the same checks done in C while decoding
are several times cheaper (benchmarks B14). The twin is not written by hand:
``wire_struct`` derives it from the model's fields (names, types, defaults),
so the two cannot drift; tests/protocol/test_wire_twins.py checks they agree
on every field of every op, and that both accept and refuse the same frames.

What the twin does not check (ROS name rules, the 64-bit range of integers,
nesting depth) is checked by its caller (``codecs.json.decode_publish``); a frame the
twin refuses takes the general path, which explains what is wrong.
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING, Annotated, Any, Literal, Protocol, Union, get_args, get_origin

import msgspec

from .base import WireAs
from .topics import Publish

if TYPE_CHECKING:
    from pydantic.fields import FieldInfo

    from .base import OpModel
    from .qos import Qos

__all__ = ["PublishFrame", "PublishView", "wire_struct"]


def _plain(annotation: Any) -> Any:
    """The annotation without pydantic's validators (``Annotated`` metadata).

    A ``WireAs`` in the metadata gives the twin's type instead.
    """
    if get_origin(annotation) is Annotated:
        given = [meta for meta in annotation.__metadata__ if isinstance(meta, WireAs)]
        if given:
            return given[0].type
        return _plain(get_args(annotation)[0])
    args = get_args(annotation)
    if args and get_origin(annotation) in (Union, type(int | str)):
        plain = tuple(_plain(arg) for arg in args)
        result = plain[0]
        for arg in plain[1:]:
            result = result | arg
        return result
    return annotation


def _field(name: str, info: FieldInfo) -> tuple[str, Any] | tuple[str, Any, Any]:
    annotation = _plain(info.annotation)
    if info.is_required():
        return (name, annotation)
    if info.default_factory is not None:
        return (name, annotation, msgspec.field(default_factory=info.default_factory))  # type: ignore[arg-type]
    return (name, annotation, info.default)


@cache
def wire_struct(model: type[OpModel]) -> type[msgspec.Struct]:
    """Generate the msgspec ``Struct`` of an op model.

    Args:
        model: an op model (``ops.Publish``, ...).

    Returns:
        A frozen Struct with a required ``op`` that must be the op's name, then
        the model's other fields in order, their types without pydantic's
        validators, and their defaults; unknown fields are ignored, as the
        model ignores them.
    """
    op = model.model_fields["op"].default
    # ``op`` is a required field, not a msgspec tag: a lone Struct accepts a
    # frame without its tag, and a frame without ``op`` is not an op (D1).
    fields: list[tuple[str, Any] | tuple[str, Any, Any]] = [("op", Literal[op])]
    fields += [_field(name, info) for name, info in model.model_fields.items() if name != "op"]
    # keyword-only: an optional field may come before a required one, as in the models
    return msgspec.defstruct(
        model.__name__ + "Frame", fields, frozen=True, kw_only=True, module=__name__
    )


PublishFrame: type[msgspec.Struct] = wire_struct(Publish)
"""``Publish`` as msgspec decodes it straight from JSON: the publish hot path (B14)."""


class PublishView(Protocol):
    """What a decoded ``publish`` offers its handler, from either decoder.

    Typing only: ``Publish`` (pydantic) and ``PublishFrame`` (generated) both
    have these attributes; tests/protocol/test_wire_twins.py checks them.
    """

    @property
    def op(self) -> Literal["publish"]:
        """The ``op`` field."""

    @property
    def topic(self) -> str:
        """The ``topic`` field."""

    @property
    def msg(self) -> Any:
        """The ``msg`` field."""

    @property
    def id(self) -> str | int | None:
        """The ``id`` field."""

    @property
    def latch(self) -> bool:
        """The ``latch`` field."""

    @property
    def type(self) -> str | None:
        """The ``type`` field (D48)."""

    @property
    def queue_size(self) -> int | None:
        """The ``queue_size`` field (read by a publish that advertises, D62)."""

    @property
    def qos(self) -> Qos | None:
        """The ``qos`` field (protocol 2.1.0): always None from the twin (D62)."""
