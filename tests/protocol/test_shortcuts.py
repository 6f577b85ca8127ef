"""The list of performance shortcuts and its switch; the codecs' shortcuts against the general path.

rwt_protocol.shortcuts is the one place that lists them (docs/shortcuts.md is
its page); ``RWT_NO_SHORTCUTS`` switches them off. The JSON and CBOR encoders'
shortcuts must give the bytes, and the CBOR decoder's the values, that the
general path gives. tests/transports/test_shortcuts_switch.py checks a whole
server.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import cbor2
import numpy as np
import pytest

from rwt_protocol import shortcuts
from rwt_protocol.codecs import cbor as codec_cbor
from rwt_protocol.codecs import json as codec
from rwt_protocol.codecs.cbor import decode_cbor, encode_cbor
from rwt_protocol.codecs.json import encode_publish_json
from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.ops import Publish
from rwt_protocol.shortcuts import ENV_VAR, SHORTCUTS, enabled, shortcut_report, switched_off

REPO = Path(__file__).resolve().parents[2]
NAMES = [s.name for s in SHORTCUTS]
SWITCHABLE = frozenset(s.name for s in SHORTCUTS)


def _resolve(path: str) -> object:
    """The object at a dotted path: the longest importable module, then attributes."""
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            found: object = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            found = getattr(found, name)
        return found
    raise ImportError(path)


def test_every_shortcut_names_code_that_exists_and_a_benchmark() -> None:
    assert len(set(NAMES)) == len(NAMES)
    scenarios = (REPO / "docs" / "benchmarks.md").read_text()
    for shortcut in SHORTCUTS:
        assert re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", shortcut.name)
        assert callable(_resolve(shortcut.module)), shortcut.module
        ids = re.findall(r"[BZ]\d+", shortcut.benchmark)
        assert ids, shortcut.name
        for scenario in ids:  # a suite scenario's row, or scaleout's Z1-Z3 (Zenoh link)
            row = f"| {scenario} |" if scenario.startswith("B") else f"{scenario} the "
            assert row in scenarios, scenario
        assert shortcut.what and shortcut.fallback


def test_the_module_docstring_and_the_docs_page_list_every_shortcut() -> None:
    page = (REPO / "docs" / "shortcuts.md").read_text()
    for shortcut in SHORTCUTS:
        assert f"``{shortcut.name}``" in (shortcuts.__doc__ or ""), shortcut.name
        row = next((line for line in page.splitlines() if f"| `{shortcut.name}` |" in line), "")
        assert row, f"docs/shortcuts.md has no row for {shortcut.name}"
        assert shortcut.module.split(".")[0] in row
        for scenario in re.findall(r"B\d+", shortcut.benchmark):
            assert scenario in row, (shortcut.name, scenario)
    assert ENV_VAR in page


@pytest.mark.parametrize(
    ("value", "off"),
    [
        ("", frozenset()),
        ("0", frozenset()),
        ("  ", frozenset()),
        ("1", SWITCHABLE),
        ("ALL", SWITCHABLE),
        ("direct-read", {"direct-read"}),
        (" ws-frame-reader ,cbor-splice-decode,", {"ws-frame-reader", "cbor-splice-decode"}),
    ],
)
def test_the_switch_value(value: str, off: frozenset[str]) -> None:
    assert switched_off(value) == off


@pytest.mark.parametrize(
    ("value", "text"),
    [
        ("direct-reed", "no shortcut named 'direct-reed'"),
        ("true", "no shortcut named 'true'"),
    ],
)
def test_a_wrong_switch_value_is_an_error_not_ignored(value: str, text: str) -> None:
    with pytest.raises(ValueError, match=text):
        switched_off(value)


def test_enabled_reads_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV_VAR, "loop-clock")
    assert not enabled("loop-clock")
    assert enabled("direct-read")
    assert enabled("publish-decode")
    monkeypatch.setenv(ENV_VAR, "1")
    assert not any(enabled(name) for name in SWITCHABLE)
    monkeypatch.delenv(ENV_VAR)
    assert all(enabled(name) for name in NAMES)
    with pytest.raises(KeyError):
        enabled("no-such-shortcut")


def test_the_report_shows_each_state() -> None:
    lines = shortcut_report("loop-clock").splitlines()
    assert len(lines) == len(SHORTCUTS)
    states = {line.split()[0]: line.split()[1] for line in lines}
    assert states["loop-clock"] == "off"
    assert states["direct-read"] == "on"
    assert states["publish-decode"] == "on"


def test_the_codecs_choose_at_import() -> None:
    """The protocol's shortcuts are chosen when their module is imported."""
    code = (
        "from rwt_protocol.codecs import cbor as codec_cbor, json as codec;"
        "print(codec._SPLICE_BASE64, codec._PUBLISH_ENCODE,"
        " codec_cbor._SPLICE_ENCODE, codec_cbor._SPLICE_DECODE)"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    for value, expected in [("1", "False False False False"), ("0", "True True True True")]:
        result = subprocess.run(
            [sys.executable, "-c", code],
            env={**env, ENV_VAR: value},
            capture_output=True,
            text=True,
            check=True,
        )
        assert result.stdout.split() == expected.split()
    bad = subprocess.run(
        [sys.executable, "-c", code],
        env={**env, ENV_VAR: "cbor-splice"},
        capture_output=True,
        check=False,
    )
    assert bad.returncode != 0 and b"no shortcut named 'cbor-splice'" in bad.stderr


def test_every_shortcut_in_the_registry_has_a_switch() -> None:
    """Each registered shortcut is chosen by ``enabled("<name>")`` somewhere in src/."""
    sources = "\n".join(
        path.read_text("utf-8")
        for path in (REPO / "src").rglob("*.py")
        if path.name != "shortcuts.py"
    )
    asked = set(re.findall(r"enabled\(\s*\"([a-z0-9-]+)\"\s*\)", sources))
    assert asked == set(NAMES)  # no switch without a shortcut, no shortcut without a switch


_OUTSIDE_THE_PROBE = """
import json, sys
from pathlib import Path

from rwt_graph.types import wire
from rwt_protocol.codecs import json as codec
from rwt_protocol.client import ClientSession

class Counting:  # counts the one-pass decoder's uses
    calls = 0
    def decode(self, frame):
        Counting.calls += 1
        return real.decode(frame)

real, codec._publish_decoder = codec._publish_decoder, Counting()
events = ClientSession().receive_frame('{"op":"publish","topic":"/a","msg":{"data":"hi"}}')

import rwt
graph = rwt.Graph()
chatter = graph.create_publisher("/chatter", "std_msgs/msg/String", latch=True)
chatter.publish({"data": "latched"})  # recorded as the recorder subscribes
path = Path(sys.argv[1]) / "bag"
async def record():
    async with rwt.bag.Recorder(graph, path, topics=["/chatter"]):
        pass
import anyio
anyio.run(record)
print(json.dumps({
    "events": [(e.op, e.topic, e.msg) for e in events],
    "kinds": [type(e).__name__ for e in events],
    "decoder_calls": Counting.calls,
    "view": type(wire.wire_input(bytes(64 * 1024))).__name__,
    "checkpoints": "rwt_bag.mcap" in sys.modules,  # imported only for CheckpointWriter
    "bag": [(t.topic, t.msgtype, t.count) for t in rwt.bag.bag_info(path).topics],
}))
"""


def _outside_the_probe(value: str, tmp_path: Path) -> dict[str, object]:
    env = {**os.environ, "PYTHONPATH": str(REPO / "src"), ENV_VAR: value}
    result = subprocess.run(
        [sys.executable, "-c", _OUTSIDE_THE_PROBE, str(tmp_path / value)],
        env=env,
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout)  # type: ignore[no-any-return]


def test_the_shortcuts_outside_the_server_probe_follow_the_switch(tmp_path: Path) -> None:
    """The client's publish decoding, the CDR input view and the bag checkpoints."""
    on = _outside_the_probe("0", tmp_path)
    off = _outside_the_probe("publish-decode,cdr-input-view,bag-checkpoints", tmp_path)
    assert on["events"] == off["events"] == [["publish", "/a", {"data": "hi"}]]
    # the fast decoder's twin of the op model, with the same fields
    assert (on["kinds"], off["kinds"]) == (["PublishFrame"], ["Publish"])
    assert (on["decoder_calls"], off["decoder_calls"]) == (1, 0)
    assert (on["view"], off["view"]) == ("memoryview", "bytes")
    assert (on["checkpoints"], off["checkpoints"]) == (True, False)
    assert on["bag"] == off["bag"] == [["/chatter", "std_msgs/msg/String", 1]]


# The encoders and the decoder, with each shortcut on and off in turn.

LARGE = 64 * 1024


def _pixels(n: int) -> bytes:
    """``n`` bytes 0, 1, ... 250, 0, 1, ...: made at collection, in every worker."""
    return (bytes(range(251)) * (n // 251 + 1))[:n]


JSON_MESSAGES = [
    {"data": "hello"},
    {"data": _pixels(LARGE - 1)},  # just below the splice size
    {"data": _pixels(LARGE), "encoding": "mono8", "height": 1},
    {"header": {"frame_id": "c"}, "a": _pixels(70000), "b": b"", "c": _pixels(LARGE * 3)},
    {"nested": {"data": _pixels(70000)}},  # only the message's own fields are spliced
]


@pytest.mark.parametrize("msg", JSON_MESSAGES, ids=range(len(JSON_MESSAGES)))
def test_json_base64_splice_gives_the_general_bytes(
    msg: dict[str, object], monkeypatch: pytest.MonkeyPatch
) -> None:
    frames = []
    for on in (True, False):
        monkeypatch.setattr(codec, "_SPLICE_BASE64", on)
        frames.append(encode_publish_json("/t", msg))
    assert frames[0] == frames[1]
    assert frames[1] == codec.encode_op(Publish(topic="/t", msg=msg))


@pytest.mark.parametrize("msg", JSON_MESSAGES, ids=range(len(JSON_MESSAGES)))
@pytest.mark.parametrize("topic", ["/t", "chatter", "/a/b\u00e9"])
def test_publish_encode_gives_the_model_bytes(
    msg: dict[str, object], topic: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The publish op written out is the op its model gives (with the splice on and off)."""
    for splice in (True, False):
        monkeypatch.setattr(codec, "_SPLICE_BASE64", splice)
        frames = []
        for on in (True, False):
            monkeypatch.setattr(codec, "_PUBLISH_ENCODE", on)
            frames.append(encode_publish_json(topic, msg))
        assert frames[0] == frames[1]


def _cbor_ops() -> list[dict[str, object]]:
    floats = np.linspace(-1, 1, 20000, dtype=np.float32)
    return [
        {"op": "publish", "topic": "/s", "msg": {"data": "hello"}},
        {"op": "publish", "topic": "/i", "msg": {"header": {"seq": 1}, "data": _pixels(LARGE)}},
        {"op": "publish", "topic": "/f", "msg": {"data": floats, "n": [1, 2.5, None, True]}},
        {"op": "publish", "topic": "/u", "msg": {"data": np.arange(70000, dtype=np.uint8)}},
        {"op": "publish", "msg": {"a": {"b": {"c": _pixels(70000)}}, "d": np.arange(30000)}},
        {"op": "service_response", "values": {"big": _pixels(LARGE * 2)}, "result": True},
    ]


@pytest.mark.parametrize("op", _cbor_ops(), ids=range(len(_cbor_ops())))
def test_cbor_splice_encode_gives_the_general_bytes(
    op: dict[str, object], monkeypatch: pytest.MonkeyPatch
) -> None:
    frames = []
    for on in (True, False):
        monkeypatch.setattr(codec_cbor, "_SPLICE_ENCODE", on)
        frames.append(encode_cbor(op))
    assert frames[0] == frames[1]
    assert frames[1] == cbor2.dumps(op, default=codec_cbor._encode_array)


def _same(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and np.array_equal(a, b)
        )
    if isinstance(a, dict) and isinstance(b, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(map(_same, a, b))
    return type(a) is type(b) and a == b


def _cbor_frames() -> list[bytes]:
    big_endian = np.arange(20000, dtype=">i4").tobytes()
    frames = [encode_cbor(op) for op in _cbor_ops()]
    frames.append(cbor2.dumps({"op": "publish", "msg": {"d": cbor2.CBORTag(74, big_endian)}}))
    frames.append(cbor2.dumps({"op": "publish", "msg": {"d": cbor2.CBORTag(64, _pixels(LARGE))}}))
    frames.append(cbor2.dumps([_pixels(LARGE)]))  # not a map: cbor2 all the way
    return frames


@pytest.mark.parametrize("typed", [True, False])
@pytest.mark.parametrize("frame", _cbor_frames(), ids=range(len(_cbor_frames())))
def test_cbor_splice_decode_gives_the_general_values(
    frame: bytes, typed: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    values = []
    for on in (True, False):
        monkeypatch.setattr(codec_cbor, "_SPLICE_DECODE", on)
        values.append(decode_cbor(frame, typed_arrays=typed))
    assert _same(values[0], values[1])


@pytest.mark.parametrize(
    "frame",
    [
        cbor2.dumps({"msg": {"data": bytes(70000)}})[:-5],
        cbor2.dumps({"msg": {"data": bytes(70000)}}) + b"\x00",
        cbor2.dumps({"msg": {"d": cbor2.CBORTag(77, bytes(70001))}}),
        cbor2.dumps({"msg": {"d": cbor2.CBORTag(99, bytes(70000))}}),
    ],
    ids=["cut short", "trailing bytes", "partial element", "unknown tag"],
)
def test_cbor_splice_decode_refuses_with_the_general_text(
    frame: bytes, monkeypatch: pytest.MonkeyPatch
) -> None:
    texts = []
    for on in (True, False):
        monkeypatch.setattr(codec_cbor, "_SPLICE_DECODE", on)
        with pytest.raises(RemoteProtocolError) as caught:
            decode_cbor(frame, typed_arrays=True)
        texts.append(str(caught.value))
    assert texts[0] == texts[1]
