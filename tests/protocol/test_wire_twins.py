"""Each op is defined once: the msgspec twins and the outgoing frames come from the models."""

from __future__ import annotations

import json
import typing
from typing import Any

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from rwt_protocol.codecs.json import encode_op, op_object, parse_object
from rwt_protocol.errors import LocalProtocolError, RemoteProtocolError
from rwt_protocol.ops import OP_MODELS, Publish, PublishFrame, PublishView, ServiceResponse, Status
from rwt_protocol.ops.wire import wire_struct

from .test_publish_fast_path import assert_decoders_agree

MODELS = sorted(OP_MODELS.items())


@pytest.mark.parametrize(("name", "model"), MODELS)
def test_twin_has_the_models_fields_defaults_and_op(name: str, model: Any) -> None:
    twin = wire_struct(model)
    fields = {f.name: f for f in msgspec.structs.fields(twin)}
    assert tuple(fields) == tuple(model.model_fields)
    assert fields["op"].required  # a frame without op is not an op (D1)
    assert fields["op"].type == typing.Literal[name]
    for field, info in model.model_fields.items():
        if field == "op":
            continue
        twin_field = fields[field]
        assert twin_field.required == info.is_required()
        if info.default_factory is not None:
            assert twin_field.default_factory is info.default_factory
        elif not info.is_required():
            assert twin_field.default == info.default
    assert msgspec.json.decode(json.dumps({"op": name, **_minimal(model)}), type=twin)


def _minimal(model: Any) -> dict[str, object]:
    """A value for each required field that both decoders accept."""
    values = {str: "/a", int: 1, float: 1.0, bool: True}
    out: dict[str, object] = {}
    for field, info in model.model_fields.items():
        if field != "op" and info.is_required():
            base = info.annotation
            options = typing.get_args(base) or (base,)
            out[field] = next((values[t] for t in options if t in values), "/a")
            if field in ("level",):
                out[field] = "error"
    return out


def test_publish_view_names_what_both_decoders_give() -> None:
    view = {n for n in dir(PublishView) if not n.startswith("_")}
    assert view == set(PublishFrame.__struct_fields__) == set(Publish.model_fields)


ids = st.one_of(
    st.none(), st.text(max_size=5), st.integers(-(2**70), 2**70), st.booleans(), st.floats()
)
values = st.one_of(st.none(), st.booleans(), st.integers(-5, 5), st.text(max_size=3), st.floats())


@given(
    topic=st.one_of(st.just("/a"), st.just("bad name!"), st.integers(), st.none()),
    op_id=ids,
    latch=values,
    msg=st.one_of(st.dictionaries(st.text(max_size=3), values, max_size=3), values),
    drop=st.sampled_from([None, "op", "topic", "msg"]),
)
def test_both_publish_decoders_accept_and_refuse_the_same_frames(
    topic: object, op_id: object, latch: object, msg: object, drop: str | None
) -> None:
    frame: dict[str, object] = {"op": "publish", "topic": topic, "msg": msg, "id": op_id}
    if latch is not None:
        frame["latch"] = latch
    if drop is not None:
        del frame[drop]
    assert_decoders_agree(json.dumps(frame))


@pytest.mark.parametrize(("name", "model"), MODELS)
def test_a_built_op_parses_back_to_the_same_op(name: str, model: Any) -> None:
    built = model(**_minimal(model))
    frame = op_object(built)
    assert next(iter(frame)) == "op" and frame["op"] == name
    assert frame.keys() - {"op"} == _minimal(model).keys()  # the defaults are not sent
    op = parse_object(json.loads(encode_op(built)))
    assert op == built  # the peer fills in the same defaults
    assert op_object(op) == frame


def test_building_leaves_out_none_and_refuses_unknown_or_missing_fields() -> None:
    reply = ServiceResponse(service="/s", result=False, values="no", id=None)
    assert list(op_object(reply).items()) == [
        ("op", "service_response"),
        ("service", "/s"),
        ("result", False),
        ("values", "no"),
    ]
    with pytest.raises(LocalProtocolError, match="unknown fields \\['sevice'\\]"):
        ServiceResponse(sevice="/s", service="/s", result=True)  # type: ignore[call-arg]
    with pytest.raises(LocalProtocolError, match="missing \\['result'\\]"):
        ServiceResponse(service="/s")  # type: ignore[call-arg]


def test_fields_go_out_in_the_models_order_whatever_the_call_order() -> None:
    status = Status(id=3, msg="m", level="error")
    assert encode_op(status) == b'{"op":"status","level":"error","msg":"m","id":3}'
    assert encode_op(Publish(topic="/t")) == b'{"op":"publish","topic":"/t"}'
    assert (
        encode_op(Publish(topic="/t", latch=False))
        == b'{"op":"publish","topic":"/t","latch":false}'
    )


def test_building_an_op_does_not_validate_and_parsing_still_does() -> None:
    # rwt's own values: a ``name#id`` echoed in a reply (D25) is not a graph name
    reply = ServiceResponse(service="/s#3", result=True, values={})
    assert op_object(reply)["service"] == "/s#3"
    with pytest.raises(RemoteProtocolError, match=r"service_response: .* at \$\.service"):
        parse_object(op_object(reply))
