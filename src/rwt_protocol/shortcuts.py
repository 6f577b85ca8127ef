"""The performance shortcuts, listed in one place, and the one switch that turns them off.

A shortcut is a second, faster path beside a general one that does the same
job: generated code, a second parser, a library's private internals. Each was
kept because a benchmark scenario (``B<n>``, docs/benchmarks.md; the measured
gains are in benchmarks/README.md) showed the gain, and tests check each one
against its general path. The general path stays in the code, and the
environment variable ``RWT_NO_SHORTCUTS`` selects it: to tell whether a bug is
a shortcut's, to measure what a shortcut still buys, or to run on a library
version whose internals changed. docs/shortcuts.md is the user's page.

``RWT_NO_SHORTCUTS`` (read by ``switched_off``):

- unset, empty or ``0``: every shortcut on;
- ``1`` or ``all``: every shortcut that has a switch off;
- ``name1,name2``: those off (unknown names are an error, not ignored, so a
  misspelt name cannot leave a shortcut on unnoticed).

Each call site asks ``enabled(name)`` once, when its module is imported or
its object built (a connection's channel or pump, a message type), never per
message. Set the variable before the process starts: a module imported
earlier keeps the choice it made.

The shortcuts (name: what; module; benchmark; general path):

- ``generated-converters``: a converter per message type generated as Python
  source and compiled (``exec``) for complete, well-typed values;
  ``rwt_graph.types.fastpath``; B14 (2.1 -> 0.67 us a small publish); the
  compiled field plan of ``rwt_graph.types.convert.compile_message``.
- ``rosbags-converters``: a converter per message type to and from rosbags'
  message objects, generated as Python source (recording and replaying bags,
  cbor-raw); ``rwt_graph.types.rosbagsfast``; B20; the field walk of
  ``rwt_graph.types.interop.to_rosbags`` / ``from_rosbags``.
- ``publish-decode``: a ``publish`` op decoded and checked by msgspec in one
  pass (``ops.wire.PublishFrame``), by the server's and the client's sessions;
  ``rwt_protocol.codecs.json.decode_publish``; B14, B1 (pydantic was 8 % of B1);
  ``decode_json`` then ``parse_object`` (pydantic).
- ``cdr-input-view``: a serialized message of 64 KiB or more handed to
  rosbags' deserializers as a ``memoryview``, so that cutting off its CDR header
  does not copy it (the Zenoh and ROS 2 links, bag replay);
  ``rwt_graph.types.wire.wire_input``; B20, B21 and the Zenoh link benchmark (a
  1 MB image: the copy was half of its 120 us decode); the ``bytes`` as they came.
- ``zenoh-deferred-encode``: a message whose top-level ``uint8[]`` values
  hold 64 KiB or more queued for the Zenoh link's outbox as it is and
  serialized by the outbox's thread before its put; ``rwt_zenoh.deferred``;
  Z3, the Zenoh link benchmark (1 MB: process A's page faults);
  ``payload.encode_message`` on the event loop, the CDR queued.
- ``zenoh-late-copy``: a remote sample of 64 KiB or more queued as Zenoh's
  ``ZBytes`` and copied to ``bytes`` on the event loop before its decode;
  ``rwt_zenoh.deferred``; Z3, the Zenoh link benchmark (1 MB: process B's page
  faults); ``ZBytes.to_bytes`` on Zenoh's callback thread.
- ``publish-encode``: a ``publish`` op to a subscriber encoded from its
  object written out, not built by the ``Publish`` model;
  ``rwt_protocol.codecs.json.encode_publish_json``; B1, B2 (the model cost
  1-2 us of a 100 B message's encoding); ``encode_op`` of ``Publish``.
- ``json-base64-splice``: large byte strings of a JSON publish base64-encoded
  by pybase64 and spliced in as ``msgspec.Raw``;
  ``rwt_protocol.codecs.json.encode_publish_json``; B6 JSON, B5 JSON;
  ``encode_json`` of the whole op.
- ``cbor-splice-encode``: large byte strings and typed arrays written between
  cbor2-encoded heads with one copy (and cbor-raw's serialization kept as
  rosbags' view for it, ``rwt_graph.types.wire``);
  ``rwt_protocol.codecs.cbor.encode_cbor``; B4, B6 (4-7 ms for 4 MiB through
  cbor2); ``cbor2.dumps`` of the whole op.
- ``cbor-splice-decode``: the first map levels of a large frame parsed here,
  large payloads taken as one slice or a numpy view
  (``rwt_protocol.codecs.cbor._Splicer``); B4, B6 (2 ms for 4 MiB through
  cbor2); cbor2's decoder on the whole frame.
- ``ws-frame-reader``: whole client data frames cut and unmasked before
  websockets' parser; ``rwt_transports.wsread.FrameReader``; B6 (CBOR 7.05 ->
  5.79 ms a cloud), B1 (55 k -> 85 k msg/s); websockets'
  ``ServerProtocol.receive_data`` on every byte.
- ``ws-frame-writer``: server data frames framed by rwt, each header made once
  for all subscribers, small frames joined into one write;
  ``rwt_transports.websocket``; B1, B2; websockets' ``send_text`` and
  ``send_binary`` per frame.
- ``direct-read``: anyio's read queue taken from its asyncio protocol without
  pausing and resuming the socket per chunk (private anyio attributes);
  ``rwt_transports.direct.DirectReader``; B6 (100 Hz Twist: -15 % CPU);
  anyio's ``SocketStream.receive``.
- ``direct-write``: bytes handed to the asyncio transport under anyio's stream
  without awaiting (private anyio attributes), a header and a large payload
  in one ``writev`` on the socket while the transport holds nothing;
  ``rwt_transports.direct.DirectWriter``; B7, B2; anyio's
  ``SocketStream.send`` from the connection's writer task.
- ``deferred-send``: an idle connection's frames written at the end of the
  reader's batch, one write per connection, from the server's flow control's
  list (``flush_deferred``); output made outside a reader (an in-process
  publisher, a link, a timer) gathered over the loop's turns while a burst goes
  on and written from the loop (``rwt_transports.gather``), whatever the
  protocol; ``rwt_transports.pump``; B7 (latency), B2 (fan-out), the Foxglove
  comparison's bursts; waking the connection's writer task for each output.
- ``foxglove-shared-frames``: a Foxglove message data frame (its 13-byte
  header and the payload) made once per message, subscription id and log
  time, and queued by every client subscribed with that id, so it is also
  framed once; ``rwt_foxglove.session._TopicSink.on_messages``; B2 (fan-out),
  the Foxglove comparison's bursts to ten readers; a frame made by each client.
- ``batched-delivery``: while a server serves the graph, serialized messages
  published in one turn of the event loop on topics whose every subscriber
  only queues output (a Foxglove client, a rosbridge client with
  ``rosbridge-batch-sink``) are delivered at the turn's end, a topic's run of
  them in one call per subscriber (``BatchSink``);
  ``rwt_graph.core.GraphCore.deliver_wire``; B2, the Foxglove comparison's bursts;
  each message delivered to each subscriber as it is published.
- ``rosbridge-batch-sink``: a rosbridge client's subscription takes a run of a
  topic's messages in one call (a turn's batch, a run of a ROS 2 publisher's
  samples), its session queueing each one-frame message in the fewest steps
  and waking the connection once;
  ``rwt_protocol.server.subscriptions.BatchTopicSubscription``; B21 (String at
  full rate to ten: 87 k -> 135 k deliveries/s), B2 (1.17x to 10, 1.21x to 100);
  ``TopicSubscription.on_message``, message by message.
- ``loop-clock``: the pump reads ``loop.time`` itself, the value
  ``anyio.current_time`` returns on asyncio; ``rwt_transports.pump``; B6
  (5 % of the 100 Hz Twist's samples); ``anyio.current_time``.
- ``ros2-batch-take``: after rclpy's executor hands the ROS 2 link one
  sample, the link takes the samples queued behind it straight from the
  subscription's handle (rclpy's private ``take_message``), up to
  ``TAKE_BATCH``; ``rwt_ros2.link``; B21 (String at full rate: 2.9 k -> 8.2 k
  msg/s; one executor wait costs more than the sample); one executor callback
  per sample.
- ``ros2-take-loop``: the ROS 2 link's topic subscriptions waited on and taken
  on a thread of their own, from an rcl wait set of those subscriptions alone
  (rclpy's private ``Subscription``, ``WaitSet`` and ``GuardCondition``), each
  wake-up's samples handed over as one batch; ``rwt_ros2.takeloop.TakeLoop``;
  B21 (String at 1 and 5 kHz); subscriptions of the node, called back by
  rclpy's single-threaded executor (with ``ros2-batch-take``).
- ``bag-checkpoints``: a rosbag2 writer that keeps an MCAP bag readable while
  it grows (a summary and ``metadata.yaml`` at each checkpoint, the new tail in
  one ``pwritev`` of rosbags' own buffers), by overriding rosbags' storage
  classes (private internals); ``rwt_bag.mcap.CheckpointWriter``; B20; rosbags'
  ``Writer``, whose bag is readable once closed.
- ``ros1-chunk-read``: a ROS 1 bag's message records read in place in each
  decompressed chunk, by rosbags' own index (private attributes of its
  ``rosbag1.Reader``); ``rwt_bag.ros1read.chunk_messages``; B22 play (about
  3 -> 1 us a message); rosbags' ``Reader.messages``.

Reading the environment is not I/O in the sense of this package's rule (no
sockets, files, clocks or threads): it is the process's configuration.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass

from .errors import ConfigError

__all__ = ["ENV_VAR", "SHORTCUTS", "Shortcut", "enabled", "shortcut_report", "switched_off"]

ENV_VAR = "RWT_NO_SHORTCUTS"
"""The environment variable that switches shortcuts off (see the module docstring)."""

_ALL = ("1", "all")
_NONE = ("", "0")


@dataclass(frozen=True, slots=True)
class Shortcut:
    """One performance shortcut.

    Attributes:
        name: the name ``RWT_NO_SHORTCUTS`` and ``enabled`` take.
        module: the dotted path of what implements it (a module's function or class).
        what: what it does instead of the general path.
        benchmark: the scenarios (docs/benchmarks.md) that justify it.
        fallback: the general path taken when it is off.
    """

    name: str
    module: str
    what: str
    benchmark: str
    fallback: str


SHORTCUTS: tuple[Shortcut, ...] = (
    Shortcut(
        "generated-converters",
        "rwt_graph.types.fastpath.compile_fast",
        "a converter per message type, generated Python source, for complete well-typed values",
        "B14",
        "rwt_graph.types.convert.compile_message (MessageType.from_json's general path)",
    ),
    Shortcut(
        "rosbags-converters",
        "rwt_graph.types.rosbagsfast.compile_to_rosbags",
        "a converter per message type to and from rosbags objects, generated Python source",
        "B20",
        "rwt_graph.types.interop.to_rosbags / from_rosbags (a walk of the fields)",
    ),
    Shortcut(
        "publish-decode",
        "rwt_protocol.codecs.json.decode_publish",
        "a publish op decoded and checked by msgspec in one pass (ops.wire.PublishFrame)",
        "B14, B1",
        "rwt_protocol.codecs.json.decode_json then parse_object (pydantic)",
    ),
    Shortcut(
        "cdr-input-view",
        "rwt_graph.types.wire.wire_input",
        "a serialized message of 64 KiB or more handed to rosbags as a view (no header copy)",
        "B20, B21, Zenoh link",
        "the bytes as they came (rosbags copies them to cut the CDR header)",
    ),
    Shortcut(
        "zenoh-deferred-encode",
        "rwt_zenoh.deferred.DeferredEncoder",
        "a message with 64 KiB or more of uint8[] serialized by the outbox thread before its put",
        "Z3 (Zenoh link, 1 MB)",
        "rwt_zenoh.payload.encode_message on the event loop, the CDR queued for the outbox",
    ),
    Shortcut(
        "zenoh-late-copy",
        "rwt_zenoh.deferred.held_payload",
        "a remote sample of 64 KiB or more queued as Zenoh's ZBytes, copied on the event loop",
        "Z3 (Zenoh link, 1 MB)",
        "ZBytes.to_bytes on Zenoh's callback thread, the bytes queued for the event loop",
    ),
    Shortcut(
        "publish-encode",
        "rwt_protocol.codecs.json.encode_publish_json",
        "a publish op's JSON object written out, not built by the Publish model",
        "B1, B2",
        "rwt_protocol.codecs.json.encode_op of Publish(topic=..., msg=...)",
    ),
    Shortcut(
        "json-base64-splice",
        "rwt_protocol.codecs.json.encode_publish_json",
        "large byte strings base64-encoded by pybase64, spliced in as msgspec.Raw",
        "B6, B5 (JSON)",
        "rwt_protocol.codecs.json.encode_json of the whole op",
    ),
    Shortcut(
        "cbor-splice-encode",
        "rwt_protocol.codecs.cbor.encode_cbor",
        "large byte strings and typed arrays written between cbor2 heads, one copy",
        "B4, B6 (CBOR)",
        "cbor2.dumps of the whole op",
    ),
    Shortcut(
        "cbor-splice-decode",
        "rwt_protocol.codecs.cbor._Splicer",
        "a large frame's first map levels parsed here, payloads as one slice or a numpy view",
        "B4, B6 (CBOR)",
        "cbor2.CBORDecoder on the whole frame",
    ),
    Shortcut(
        "ws-frame-reader",
        "rwt_transports.wsread.FrameReader",
        "whole client data frames cut and unmasked ahead of websockets' parser",
        "B6, B1, B2",
        "websockets' ServerProtocol.receive_data on every byte",
    ),
    Shortcut(
        "ws-frame-writer",
        "rwt_transports.websocket._framed",
        "server data frames framed once for all subscribers, small ones joined in one write",
        "B1, B2",
        "websockets' ServerProtocol.send_text / send_binary per frame",
    ),
    Shortcut(
        "batched-delivery",
        "rwt_graph.core.GraphCore.deliver_wire",
        "a turn's serialized publishes to queueing subscribers delivered at its end, in runs",
        "B2 (fan-out), Foxglove bursts to 1 and 10 readers",
        "rwt_graph.core.GraphCore.deliver, each message to each subscriber as it is published",
    ),
    Shortcut(
        "rosbridge-batch-sink",
        "rwt_protocol.server.subscriptions.BatchTopicSubscription",
        "a run of a topic's messages taken by a rosbridge subscription in one call, each"
        " one-frame message queued in the fewest steps and the connection woken once",
        "B21 (String at full rate to 10), B2 (fan-out to 10 and 100)",
        "rwt_protocol.server.subscriptions.TopicSubscription.on_message, message by message",
    ),
    Shortcut(
        "direct-read",
        "rwt_transports.direct.DirectReader",
        "anyio's read queue taken without pausing the socket per chunk (private attributes)",
        "B6 (100 Hz Twist)",
        "anyio SocketStream.receive",
    ),
    Shortcut(
        "direct-write",
        "rwt_transports.direct.DirectWriter",
        "bytes handed to the asyncio transport under anyio's stream without awaiting",
        "B7, B2",
        "anyio SocketStream.send from the connection's writer task",
    ),
    Shortcut(
        "deferred-send",
        "rwt_transports.pump.flush_deferred",
        "an idle connection written at the end of the reader's batch (flow control's list);"
        " output made outside a reader gathered over loop turns (rwt_transports.gather)",
        "B7, B2, Foxglove bursts",
        "waking the connection's writer task (ConnectionPump._writer)",
    ),
    Shortcut(
        "foxglove-shared-frames",
        "rwt_foxglove.session._TopicSink.on_messages",
        "a Foxglove message data frame made once per message and subscription id,"
        " shared by the clients subscribed with that id",
        "B2 (fan-out), Foxglove bursts to 10 readers",
        "a frame made by each client (its header before the shared payload)",
    ),
    Shortcut(
        "loop-clock",
        "rwt_transports.pump._clock",
        "the event loop's time read directly, as anyio.current_time does on asyncio",
        "B6 (100 Hz Twist)",
        "anyio.current_time",
    ),
    Shortcut(
        "ros2-batch-take",
        "rwt_ros2.link.Ros2Link._subscribe",
        "the samples queued behind the one rclpy's executor handed over, taken from the handle",
        "B21 (String at full rate)",
        "one rclpy executor callback per sample",
    ),
    Shortcut(
        "ros2-take-loop",
        "rwt_ros2.takeloop.TakeLoop",
        "the link's subscriptions taken on a thread of their own, from a wait set of them alone",
        "B21 (String at 1 and 5 kHz)",
        "node subscriptions called back by rclpy's single-threaded executor",
    ),
    Shortcut(
        "bag-checkpoints",
        "rwt_bag.mcap.CheckpointWriter",
        "an MCAP bag kept readable while it grows, by overriding rosbags' storage internals",
        "B20",
        "rosbags.rosbag2.Writer (the bag is readable once closed)",
    ),
    Shortcut(
        "ros1-chunk-read",
        "rwt_bag.ros1read.chunk_messages",
        "a ROS 1 bag's message records read in place in each chunk (rosbags' private index)",
        "B22 (play)",
        "rosbags.rosbag1.Reader.messages (a header dict per record)",
    ),
)
"""Every shortcut, in the order of a message's way from decoding to the socket."""

_BY_NAME = {shortcut.name: shortcut for shortcut in SHORTCUTS}


def switched_off(value: str | None = None) -> frozenset[str]:
    """The names of the shortcuts that ``RWT_NO_SHORTCUTS`` turns off.

    Args:
        value: the variable's value; None reads the environment.

    Raises:
        ConfigError: the value names a shortcut that does not exist (a typo
            must not leave the shortcut on unnoticed).
    """
    return _parse(os.environ.get(ENV_VAR, "") if value is None else value)


@functools.lru_cache(maxsize=8)  # asked once per connection: parse each value once
def _parse(value: str) -> frozenset[str]:
    value = value.strip()
    if value.lower() in _NONE:
        return frozenset()
    if value.lower() in _ALL:
        return frozenset(_BY_NAME)
    names = frozenset(part.strip() for part in value.split(",") if part.strip())
    for name in sorted(names):
        shortcut = _BY_NAME.get(name)
        if shortcut is None:
            known = ", ".join(_BY_NAME)
            raise ConfigError(f"{ENV_VAR}: no shortcut named {name!r} (known: {known})")
    return names


def enabled(name: str) -> bool:
    """Whether the shortcut ``name`` is on in this process's environment.

    Call it once per module import or object construction, not per message.

    Raises:
        KeyError: no shortcut has that name (a bug at the call site).
        ConfigError: ``RWT_NO_SHORTCUTS`` is invalid (see ``switched_off``).
    """
    if name not in _BY_NAME:
        raise KeyError(name)
    return name not in switched_off()


def shortcut_report(value: str | None = None) -> str:
    """A text table of every shortcut, whether it is on, and its benchmark and fallback.

    Args:
        value: a ``RWT_NO_SHORTCUTS`` value; None reads the environment.

    Returns:
        one line per shortcut (docs/shortcuts.md): its name, ``on`` or ``off``,
        the benchmark that shows its gain and the general path it falls back to.

    Raises:
        ConfigError: ``value`` names a shortcut that does not exist.
    """
    off = switched_off(value)
    width = max(len(s.name) for s in SHORTCUTS)
    lines = []
    for s in SHORTCUTS:
        state = "off" if s.name in off else "on"
        lines.append(f"{s.name:<{width}}  {state:<14}  {s.benchmark:<17}  fallback: {s.fallback}")
    return "\n".join(lines)
