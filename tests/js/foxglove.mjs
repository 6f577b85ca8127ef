#!/usr/bin/env node
// The real Foxglove WebSocket client (@foxglove/ws-protocol's FoxgloveClient) against rwt.
// Schemas are parsed by @foxglove/rosmsg (ros2: true) and payloads decoded by
// @foxglove/rosmsg2-serialization, as Foxglove and Lichtblick do; the rosbridge
// side of each scenario is roslib on the same server.
//
// Usage: node foxglove.mjs SCENARIO WS_URL [ARGS...]
//   handshake URL PROTOCOLS   offer PROTOCOLS (comma-separated); report the selected one,
//                             serverInfo and the parsed schemas of /fg_string and /fg_image
//   stream URL                subscribe, messages in order, a 2 MB image, unsubscribe,
//                             a topic that appears and goes
//   bad URL                   bad inputs, each answered with a status; the connection goes on
//   two URL                   two clients on /fg_two_a and /fg_two_b (roslib publishers):
//                             each gets its own subscriptions' messages; one unsubscribes
//                             and leaves, the other still gets them
//   publish URL               advertise /fg_from_fox in cdr and in json, send one message each
//   services URL              call /fg_add, /fg_refuse and /fg_hold (roslibpy providers) and
//                             a few bad calls at once; signal "answered" when all but the
//                             /fg_hold call are; report each answer by call id, in order
//   params URL                set and get parameters of its own node, subscribe to them, signal
//                             "subscribed" (with the node), then report the updates from rosapi
//                             and another client
//   graph URL                 follow the connection graph; signal "following", report
//                             /fg_graph_topic's publishers, signal "seen", report it removed
//   latched URL TOPIC         subscribe to TOPIC (a latched topic already published); report
//                             its schema name and the first message, decoded
// Stdout's last line: {"result": {...}}; lines {"event": NAME} before it tell the test
// where the scenario is. Every wait is bounded.
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import * as ROSLIB from "roslib";
import WebSocket from "ws";
import { bounded, foxglove as connect } from "./foxglove_client.mjs";

const { MessageReader, MessageWriter } = serialization;
const [scenario, url, ...args] = process.argv.slice(2);
const IMAGE_BYTES = 2 * 1024 * 1024;

// A Foxglove connection to this scenario's URL (the shared client: foxglove_client.mjs).
function foxglove(protocols) {
  return connect(url, protocols);
}

// Tell the test something happened ({"event": NAME} on stdout).
function signal(name) {
  process.stdout.write(`${JSON.stringify({ event: name })}\n`);
}

function rosbridge() {
  return bounded(
    new Promise((resolve, reject) => {
      const ros = new ROSLIB.Ros({ url });
      ros.on("connection", () => resolve(ros));
      ros.on("error", (error) => reject(new Error(`roslib: ${error}`)));
    }),
    "roslib connection",
  );
}

function reader(channel) {
  return new MessageReader(rosmsg.parse(channel.schema, { ros2: true }));
}

function summary(channel) {
  const definitions = rosmsg.parse(channel.schema, { ros2: true });
  return {
    encoding: channel.encoding,
    schemaName: channel.schemaName,
    schemaEncoding: channel.schemaEncoding,
    types: definitions.map((d) => ({
      name: d.name ?? null,
      fields: d.definitions.filter((f) => !f.isConstant).map((f) => `${f.type} ${f.name}`),
    })),
  };
}

function imageData(size) {
  const data = Buffer.alloc(size);
  for (let i = 0; i < size; i += 1) data[i] = i % 251;
  return data;
}

async function handshake() {
  const ros = await rosbridge();
  const str = new ROSLIB.Topic({ ros, name: "/fg_string", messageType: "std_msgs/msg/String" });
  const img = new ROSLIB.Topic({ ros, name: "/fg_image", messageType: "sensor_msgs/msg/Image" });
  str.advertise();
  img.advertise();
  const fox = foxglove(args[0].split(","));
  const { info } = await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const result = {
    protocol: fox.ws.protocol,
    serverInfo: info,
    string: summary(await fox.channel("/fg_string")),
    image: summary(await fox.channel("/fg_image")),
  };
  fox.client.close();
  ros.close();
  return result;
}

async function stream() {
  const ros = await rosbridge();
  const str = new ROSLIB.Topic({ ros, name: "/fg_chatter", messageType: "std_msgs/msg/String" });
  const img = new ROSLIB.Topic({ ros, name: "/fg_camera", messageType: "sensor_msgs/msg/Image" });
  str.advertise();
  img.advertise();
  const fox = foxglove(["foxglove.sdk.v1"]);
  const chatter = await fox.channel("/fg_chatter");
  const camera = await fox.channel("/fg_camera");
  const chatterSub = fox.client.subscribe(chatter.id);
  const cameraSub = fox.client.subscribe(camera.id);
  // roslib sends each op when called: the subscriptions are in before the first publish
  // only once the server has handled them; a status answers a probe sent after them.
  fox.ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [999999] }));
  await fox.next((e) => e.kind === "status", "the probe's status");
  const texts = ["one", "two", "three", "four", "five"];
  for (const data of texts) str.publish({ data });
  const big = imageData(IMAGE_BYTES);
  img.publish({
    header: { stamp: { sec: 1700000000, nanosec: 5 }, frame_id: "cam" },
    height: 1024,
    width: 1024,
    encoding: "rgb8",
    is_bigendian: 0,
    step: 2048,
    data: big.toString("base64"),
  });
  const chatterReader = reader(chatter);
  const cameraReader = reader(camera);
  const got = [];
  let image = null;
  while (got.length < texts.length || image === null) {
    const { message } = await fox.next((e) => e.kind === "message", "message data");
    if (message.subscriptionId === chatterSub) {
      got.push(chatterReader.readMessage(message.data).data);
    } else if (message.subscriptionId === cameraSub) {
      const decoded = cameraReader.readMessage(message.data);
      image = {
        stamp: [decoded.header.stamp.sec, decoded.header.stamp.nanosec],
        frame_id: decoded.header.frame_id,
        size: [decoded.height, decoded.width, decoded.step],
        length: decoded.data.length,
        intact: Buffer.from(decoded.data).equals(big),
        logTimeOk: message.timestamp > 1600000000n * 1000000000n,
      };
    }
  }
  // Unsubscribed, /fg_chatter's next message must not come; the marker on /fg_camera,
  // published after it, arrives after where it would have been (one queue, in order).
  fox.client.unsubscribe(chatterSub);
  fox.ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [999998] }));
  await fox.next((e) => e.kind === "status", "the second probe's status");
  str.publish({ data: "after unsubscribe" });
  img.publish({ header: { frame_id: "marker" }, encoding: "mono8", data: "" });
  const after = [];
  for (;;) {
    const { message } = await fox.next((e) => e.kind === "message", "the marker");
    if (message.subscriptionId === cameraSub) break;
    after.push(message.subscriptionId);
  }
  // A topic that appears and goes.
  const late = new ROSLIB.Topic({ ros, name: "/fg_late", messageType: "std_msgs/msg/Int32" });
  late.advertise();
  const lateChannel = await fox.channel("/fg_late");
  late.unadvertise();
  const gone = await fox.next(
    (e) => e.kind === "unadvertise" && e.ids.includes(lateChannel.id),
    "unadvertise /fg_late",
  );
  fox.client.close();
  ros.close();
  return {
    got,
    image,
    afterUnsubscribe: after,
    late: { advertised: lateChannel.schemaName, unadvertised: gone.ids },
    errors: fox.statuses.filter((s) => !String(s.message).includes("99999")),
  };
}

async function bad() {
  const ros = await rosbridge();
  const latched = new ROSLIB.Topic({
    ros,
    name: "/fg_latched",
    messageType: "std_msgs/msg/String",
    latch: true,
  });
  latched.publish({ data: "still here" });
  const fox = foxglove(["foxglove.websocket.v1"]);
  const channel = await fox.channel("/fg_latched");
  const mine = fox.client.advertise({ topic: "/fg_bad_in", encoding: "cdr", schemaName: "std_msgs/msg/String" });
  const le32 = (n) => {
    const b = Buffer.alloc(4);
    b.writeUInt32LE(n);
    return b;
  };
  const inputs = {
    unknownOp: JSON.stringify({ op: "frobnicate" }),
    malformedJson: '{"op": "subscribe", ',
    unknownOpcode: Buffer.from([0x7f, 1, 2, 3]),
    unknownChannel: JSON.stringify({ op: "subscribe", subscriptions: [{ id: 1, channelId: 424242 }] }),
    unknownSubscription: JSON.stringify({ op: "unsubscribe", subscriptionIds: [31337] }),
    unknownClientChannel: Buffer.from([0x01, 0x39, 0x05, 0x00, 0x00, 0x68, 0x69]),
    truncatedBinary: Buffer.from([0x01, 0x00]),
    hugeLength: JSON.stringify({
      op: "advertise",
      channels: [{ id: 77, topic: `/${"a".repeat(1 << 20)}`, encoding: "json", schemaName: "std_msgs/msg/String" }],
    }),
    // a service call whose encoding name is 4 GiB long; a CDR string of length 0xfffffff0
    hugeLengthInBinary: Buffer.concat([Buffer.from([0x02]), le32(1), le32(1), le32(0xffffffff), Buffer.from("cdr")]),
    hugeCdrLength: Buffer.concat([Buffer.from([0x01]), le32(mine), Buffer.from([0, 1, 0, 0]), le32(0xfffffff0), Buffer.from("hi\0")]),
    hugeId: '{"op": "subscribe", "subscriptions": [{"id": 4294967296, "channelId": 1}]}',
    loneSurrogate: '{"op": "unsubscribe", "subscriptionIds": [], "note": "\\ud800"}',
    hugeInt: '{"op": "unsubscribe", "subscriptionIds": [123456789012345678901234567890]}',
  };
  const answers = {};
  for (const [name, frame] of Object.entries(inputs)) {
    fox.ws.send(frame);
    const { status } = await fox.next((e) => e.kind === "status", `the status for ${name}`);
    answers[name] = status;
  }
  const sid = fox.client.subscribe(channel.id);
  const { message } = await fox.next((e) => e.kind === "message", "the latched message");
  const result = {
    answers,
    latched: message.subscriptionId === sid ? reader(channel).readMessage(message.data).data : null,
    open: fox.ws.readyState === WebSocket.OPEN,
  };
  fox.client.close();
  ros.close();
  return result;
}

async function two() {
  const ros = await rosbridge();
  const topics = ["/fg_two_a", "/fg_two_b"].map((name) => {
    const topic = new ROSLIB.Topic({ ros, name, messageType: "std_msgs/msg/String" });
    topic.advertise();
    return topic;
  });
  const one = foxglove(["foxglove.sdk.v1"]);
  const other = foxglove(["foxglove.websocket.v1"]);
  const oneA = await one.channel("/fg_two_a");
  const otherA = await other.channel("/fg_two_a");
  const otherB = await other.channel("/fg_two_b");
  const subs = {
    [one.client.subscribe(oneA.id)]: "a",
  };
  const otherSubs = {
    [other.client.subscribe(otherA.id)]: "a",
    [other.client.subscribe(otherB.id)]: "b",
  };
  // each is subscribed once a status answers a probe sent after its subscriptions
  for (const fox of [one, other]) {
    fox.ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [999999] }));
    await fox.next((e) => e.kind === "status", "the probe's status");
  }
  const decode = reader(oneA);
  const take = async (fox, ids, until) => {
    const got = [];
    while (got.at(-1) !== until) {
      const { message } = await fox.next((e) => e.kind === "message", `messages until ${until}`);
      got.push(`${ids[message.subscriptionId] ?? message.subscriptionId}:${decode.readMessage(message.data).data}`);
    }
    return got;
  };
  topics[0].publish({ data: "a1" });
  topics[1].publish({ data: "b1" });
  topics[0].publish({ data: "a2" });
  const oneGot = await take(one, subs, "a:a2");
  const otherGot = await take(other, otherSubs, "a:a2");
  // one unsubscribes and leaves; the other goes on
  one.client.unsubscribe(Number(Object.keys(subs)[0]));
  one.ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [999998] }));
  await one.next((e) => e.kind === "status", "the second probe's status");
  topics[0].publish({ data: "a3" });
  topics[1].publish({ data: "b2" });
  // the other got them: the server handled both publishes before the third probe
  const otherAfter = await take(other, otherSubs, "b:b2");
  const oneAfter = [];
  one.ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [999997] }));
  for (;;) {
    const event = await one.next((e) => e.kind === "status" || e.kind === "message", "the third probe");
    if (event.kind === "status") break;
    oneAfter.push(event.message.subscriptionId);
  }
  one.client.close();
  topics[0].publish({ data: "a4" });
  const otherLast = await take(other, otherSubs, "a:a4");
  other.client.close();
  ros.close();
  return { oneGot, otherGot, oneAfter, otherAfter, otherLast, statuses: [...one.statuses, ...other.statuses].length };
}

async function publish() {
  const fox = foxglove(["foxglove.sdk.v1"]);
  await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const string = rosmsg.parse("string data\n", { ros2: true });
  const cdr = fox.client.advertise({
    topic: "/fg_from_fox",
    encoding: "cdr",
    schemaName: "std_msgs/msg/String",
    schema: "string data\n",
    schemaEncoding: "ros2msg",
  });
  const json = fox.client.advertise({
    topic: "/fg_from_fox",
    encoding: "json",
    schemaName: "std_msgs/msg/String",
  });
  fox.client.sendMessage(cdr, new MessageWriter(string).writeMessage({ data: "from cdr" }));
  fox.client.sendMessage(json, new TextEncoder().encode(JSON.stringify({ data: "from json" })));
  fox.client.unadvertise(cdr);
  fox.client.sendMessage(cdr, new MessageWriter(string).writeMessage({ data: "withdrawn" }));
  const { status } = await fox.next((e) => e.kind === "status", "the withdrawn channel's status");
  fox.client.close();
  return { status };
}

const BIG = 2n ** 62n + 1n; // past 2^53: exact only as int64 end to end

function writer(definition) {
  return new MessageWriter(rosmsg.parse(definition.schema, { ros2: true }));
}

async function services() {
  const fox = foxglove(["foxglove.sdk.v1"]);
  const add = await fox.service("/fg_add");
  const refuse = await fox.service("/fg_refuse");
  const hold = await fox.service("/fg_hold");
  const call = (service, callId, data, encoding = "cdr") =>
    fox.client.sendServiceCallRequest({ serviceId: service.id, callId, encoding, data });
  const addRequest = (a, b) => writer(add.request).writeMessage({ a, b });
  call(hold, 1, writer(hold.request).writeMessage({ a: 1n, b: 1n })); // answered by nobody
  call(add, 2, addRequest(BIG, 1n));
  call(add, 3, addRequest(-5n, 3n));
  call(refuse, 4, writer(refuse.request).writeMessage({ data: true }));
  call({ id: 999999 }, 5, addRequest(1n, 1n));
  call(add, 6, new TextEncoder().encode('{"a": 1, "b": 2}'), "json");
  call(add, 7, new Uint8Array([0, 1, 0, 0, 1])); // a CDR header, then too few bytes
  const responseReader = new MessageReader(rosmsg.parse(add.response.schema, { ros2: true }));
  const answers = {};
  const order = [];
  const take = async () => {
    const { response, failure } = await fox.next((e) => e.kind === "answer", "the answers");
    const answer = response ?? failure;
    order.push(answer.callId);
    answers[answer.callId] = response
      ? { sum: String(responseReader.readMessage(response.data).sum), encoding: response.encoding }
      : { failure: failure.message, serviceId: failure.serviceId };
  };
  while (order.length < 6) await take(); // every call but the held one
  signal("answered"); // the test takes /fg_hold's provider away
  await take();
  fox.client.close();
  const describe = (s) => ({
    type: s.type,
    request: [s.request.encoding, s.request.schemaName, s.request.schemaEncoding],
    response: [s.response.encoding, s.response.schemaName, s.response.schemaEncoding],
  });
  return { add: describe(add), refuse: describe(refuse), ids: [add.id, refuse.id, hold.id], answers, order };
}

async function params() {
  const fox = foxglove(["foxglove.sdk.v1"]);
  const other = foxglove(["foxglove.sdk.v1"]);
  const { info } = await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  // a client creates parameters on its own node (docs/decisions.md, D34): the node the
  // connection graph names as the publisher of a channel it advertises
  fox.client.advertise({ topic: "/fg_params_owner", encoding: "json", schemaName: "std_msgs/msg/String" });
  fox.client.subscribeConnectionGraph();
  const owned = (e) => e.kind === "graph" && e.update.publishedTopics.some((t) => t.name === "/fg_params_owner");
  const { update } = await fox.next(owned, "its own node in the connection graph");
  const node = update.publishedTopics.find((t) => t.name === "/fg_params_owner").publisherIds[0];
  fox.client.unsubscribeConnectionGraph();
  const values = (id) =>
    fox.next((e) => e.kind === "parameterValues" && e.values.id === id, `parameterValues ${id}`);
  fox.client.setParameters(
    [
      { name: `${node}.fg_gain`, value: 1, type: "float64" },
      { name: `${node}.fg_mode`, value: "auto" },
      { name: "/fg_ghost.x", value: 1 },
      { name: "/rosapi.fg_gain", value: 1 },
    ],
    "set1",
  );
  const { status } = await fox.next((e) => e.kind === "status", "the ghost node's status");
  const { status: server } = await fox.next((e) => e.kind === "status", "the server node's status");
  const set = (await values("set1")).values.parameters;
  fox.client.getParameters([`${node}.fg_gain`, `${node}.fg_mode`, `${node}.fg_none`], "get1");
  const got = (await values("get1")).values.parameters;
  fox.client.subscribeParameterUpdates([`${node}.fg_gain`, `${node}.fg_mode`]);
  fox.client.getParameters([], "probe"); // answered after the subscription is in
  await values("probe");
  process.stdout.write(`${JSON.stringify({ event: "subscribed", node })}\n`);
  const changeOf = (name) =>
    fox.next(
      (e) => e.kind === "parameterValues" && e.values.id === undefined && e.values.parameters.some((p) => p.name === name),
      `the update of ${name}`,
    );
  const fromRosapi = (await changeOf(`${node}.fg_gain`)).values.parameters;
  await other.next((e) => e.kind === "serverInfo", "the other's serverInfo");
  other.client.setParameters([{ name: `${node}.fg_mode`, value: "manual" }]); // a change: allowed
  const fromOther = (await changeOf(`${node}.fg_mode`)).values.parameters;
  fox.client.close();
  other.client.close();
  return { capabilities: info.capabilities, node, status, server, set, got, fromRosapi, fromOther };
}

async function graph() {
  const fox = foxglove(["foxglove.sdk.v1"]);
  await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  fox.client.subscribeConnectionGraph();
  const { update: first } = await fox.next((e) => e.kind === "graph", "the whole graph");
  signal("following");
  const published = await fox.next(
    (e) => e.kind === "graph" && e.update.publishedTopics.some((t) => t.name === "/fg_graph_topic"),
    "/fg_graph_topic published",
  );
  signal("seen");
  const removed = await fox.next(
    (e) => e.kind === "graph" && e.update.removedTopics.includes("/fg_graph_topic"),
    "/fg_graph_topic removed",
  );
  fox.client.close();
  return {
    first: {
      services: first.advertisedServices.map((s) => s.name),
      published: first.publishedTopics.map((t) => t.name),
      removedTopics: first.removedTopics,
    },
    publishers: published.update.publishedTopics.find((t) => t.name === "/fg_graph_topic").publisherIds,
    removedTopics: removed.update.removedTopics,
  };
}

async function latched() {
  const fox = foxglove(["foxglove.sdk.v1"]);
  const channel = await fox.channel(args[0]);
  const sub = fox.client.subscribe(channel.id);
  const { message } = await fox.next(
    (e) => e.kind === "message" && e.message.subscriptionId === sub,
    "the latched message",
  );
  const decoded = reader(channel).readMessage(message.data);
  fox.client.close();
  const plain = (value) =>
    value instanceof Uint8Array ? { bytes: value.length, sum: value.reduce((a, b) => a + b, 0) } : value;
  return {
    schemaName: channel.schemaName,
    message: Object.fromEntries(Object.entries(decoded).map(([k, v]) => [k, plain(v)])),
    payload: Buffer.from(message.data.buffer, message.data.byteOffset, message.data.byteLength).toString("hex"),
  };
}

const scenarios = { handshake, stream, bad, two, publish, services, params, graph, latched };
try {
  const result = await scenarios[scenario]();
  process.stdout.write(`${JSON.stringify({ result }, (_, v) => (typeof v === "bigint" ? String(v) : v))}\n`);
  process.exit(0);
} catch (error) {
  process.stderr.write(`${error.stack ?? error}\n`);
  process.exit(1);
}
