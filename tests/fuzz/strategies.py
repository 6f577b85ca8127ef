"""Hypothesis strategies for rosbridge ops and hostile frames, built on ``grammar``.

``valid_ops`` draws each op of the spec with valid shapes; ``hostile_ops`` the
same with fields replaced by hostile values; ``param_ops`` rosapi parameter calls
with hostile JSON texts; ``frames`` mixes those (JSON or CBOR) with raw hostile
frames. The op name is drawn by hypothesis (it shrinks
to the simplest op); the rest from a hypothesis-seeded ``random.Random``.
"""

from __future__ import annotations

import random
from typing import Any

from hypothesis import strategies as st

from tests.fuzz import grammar

op_names = st.sampled_from(grammar.OP_NAMES)
seeded = st.randoms(use_true_random=False)


@st.composite
def valid_ops(draw: st.DrawFn) -> dict[str, Any]:
    """Any op of the spec with valid field shapes."""
    name, rng = draw(op_names), draw(seeded)
    return grammar.valid_op(rng, name)


@st.composite
def hostile_ops(draw: st.DrawFn) -> dict[str, Any]:
    """An op of the spec with one to three fields replaced by hostile values."""
    name, rng = draw(op_names), draw(seeded)
    return grammar.hostile_op(rng, name)


@st.composite
def param_ops(draw: st.DrawFn) -> dict[str, Any]:
    """A rosapi parameter call carrying a (often hostile) JSON text."""
    return grammar.param_op(draw(seeded))


@st.composite
def raw_frames(draw: st.DrawFn) -> tuple[bytes, bool]:
    """A raw hostile frame: (bytes, binary)."""
    return grammar.raw_frames(draw(seeded))


def encoded(op: Any, binary: bool) -> tuple[bytes, bool]:
    """``op`` as a CBOR (binary) or JSON frame."""
    return (grammar.to_cbor(op), True) if binary else (grammar.to_json(op), False)


def frames(
    binary_ok: bool = True, max_bytes: int | None = None
) -> st.SearchStrategy[tuple[bytes, bool]]:
    """One fuzzed frame (bytes, binary); ``max_bytes`` cuts it to fit a datagram."""
    ops = st.one_of(valid_ops(), hostile_ops(), param_ops())
    as_binary = st.booleans() if binary_ok else st.just(False)
    strategy = st.one_of(st.builds(encoded, ops, as_binary), raw_frames())
    if not binary_ok:
        strategy = strategy.map(lambda f: (f[0].hex().encode(), False) if f[1] else f)
    if max_bytes is not None:
        limit = max_bytes
        strategy = strategy.map(lambda f: (f[0][:limit], f[1]))  # truncated: hostile too
    return strategy


def sequences(
    binary_ok: bool = True, max_bytes: int | None = None
) -> st.SearchStrategy[list[tuple[bytes, bool]]]:
    """A short burst of fuzzed frames sent on one connection."""
    return st.lists(frames(binary_ok, max_bytes), min_size=1, max_size=6)


@st.composite
def player_calls(draw: st.DrawFn) -> tuple[bytes, bool]:
    """A call of a bag player's service, valid or hostile, as a JSON or CBOR frame."""
    rng, binary = draw(seeded), draw(st.booleans())
    return encoded(grammar.player_call(rng), binary)


def rng_for(seed: int) -> random.Random:
    """A seeded generator for the benchmark's grammar-driven frames."""
    return random.Random(seed)


@st.composite
def zenoh_peer_actions(draw: st.DrawFn) -> list[tuple[str, Any]]:
    """What a hostile Zenoh peer does, in order: ``("token", key)`` declares a
    liveliness token (``grammar.zenoh_token``, under a zid of its choosing: a peer
    may claim any), ``("untoken", key)`` withdraws one, ``("sample", (topic,
    payload, attachment))`` puts a sample (``grammar.zenoh_sample``)."""
    rng = draw(seeded)
    zid = rng.randbytes(16).hex()
    actions: list[tuple[str, Any]] = []
    declared: list[str] = []
    for n in range(draw(st.integers(1, 12))):
        roll = rng.random()
        if roll < 0.4:
            declared.append(grammar.zenoh_token(rng, zid, n + 2))
            actions.append(("token", declared[-1]))
        elif roll < 0.5 and declared:
            actions.append(("untoken", declared.pop(rng.randrange(len(declared)))))
        else:
            actions.append(("sample", grammar.zenoh_sample(rng)))
    return actions
