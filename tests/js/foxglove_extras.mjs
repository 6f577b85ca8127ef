#!/usr/bin/env node
// The real Foxglove client against rwt: pass-through payloads, a Foxglove publisher, server
// time during a bag's replay, assets. Payloads are decoded by @foxglove/rosmsg2-serialization.
//
// Usage: node foxglove_extras.mjs SCENARIO WS_URL [ARGS...]
//   receive URL TOPIC COUNT  subscribe TOPIC; its first COUNT payloads (hex) and log times
//   publish URL TOPIC TEXT   advertise TOPIC (std_msgs/msg/String, cdr); send TEXT every
//                            100 ms for 15 s, or until the server closes
//   play URL TOPIC COUNT     (rwt serve --play --start-paused) subscribe TOPIC, resume with
//                            /rwt/player/resume; COUNT messages and the time frames among
//                            them; then seek to 0 (/rwt/player/seek) and report the first time
//                            frame and message after the step back
//   assets URL URI...        fetchAsset each URI (request ids 1, 2, ...); each response
//   call URL SERVICE JSON    call SERVICE once it is advertised, with the request JSON
//                            written in CDR by the advertised request schema; the service's
//                            description and the decoded response (or the failure)
//   params URL NODE VALUE    read NODE's speed and mode (asked again every 200 ms until both
//                            are there), watch speed, set it to VALUE (float64); the values
//                            read, the set's answer and the update pushed for it
//   param URL NAME TYPE JSON read the parameter NAME (asked again until it is there), watch
//                            it, set it to the value JSON with type TYPE; the value read, the
//                            set's answer and the update pushed for it
//   watch URL NAME COUNT     read the parameter NAME (asked again until it is there), watch
//                            it; its value read and the next COUNT values pushed
//   graph URL TOPIC          follow the connection graph until TOPIC is published and
//                            subscribed to; its publisher and subscriber ids
//   collect URL TOPIC END    subscribe to TOPIC (std_msgs/msg/String); the data of what
//                            arrives until a message whose data is END does
//   robot URL                a robot whose program is roslib: it subscribes to /cmd_vel and
//                            /tf, advertises the service /reset and the topic /chatter (in
//                            that order, so once /chatter is a channel all are in the
//                            graph); then the Foxglove client's whole connection graph, the
//                            channels and the services it was told of
// Stdout's last line: {"result": {...}}.
import { createHash } from "node:crypto";
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import * as ROSLIB from "roslib";
import { bounded, foxglove, main } from "./foxglove_client.mjs";

const { MessageReader, MessageWriter } = serialization;
const [scenario, url, ...args] = process.argv.slice(2);

function reader(channel) {
  return new MessageReader(rosmsg.parse(channel.schema, { ros2: true }));
}

function hex(view) {
  return Buffer.from(view.buffer, view.byteOffset, view.byteLength).toString("hex");
}

async function receive() {
  const [topic, count] = [args[0], Number(args[1])];
  const fox = foxglove(url);
  const channel = await fox.channel(topic);
  const sid = fox.client.subscribe(channel.id);
  const payloads = [];
  while (payloads.length < count) {
    const { message } = await fox.next(
      (e) => e.kind === "message" && e.message.subscriptionId === sid,
      `a message on ${topic}`,
    );
    payloads.push({ hex: hex(message.data), logTime: message.timestamp });
  }
  const decoded = reader(channel).readMessage(new Uint8Array(Buffer.from(payloads[0].hex, "hex")));
  fox.client.close();
  return { encoding: channel.encoding, schemaName: channel.schemaName, payloads, decoded };
}

async function publish() {
  const [topic, text] = args;
  const fox = foxglove(url);
  await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const channel = fox.client.advertise({
    topic,
    encoding: "cdr",
    schemaName: "std_msgs/msg/String",
    schema: "string data\n",
    schemaEncoding: "ros2msg",
  });
  const data = new MessageWriter(rosmsg.parse("string data\n", { ros2: true })).writeMessage({
    data: text,
  });
  let sent = 0;
  const end = Date.now() + 15000;
  while (Date.now() < end && fox.ws.readyState === fox.ws.OPEN) {
    fox.client.sendMessage(channel, data);
    sent += 1;
    await new Promise((resolve) => setTimeout(resolve, 100));
  }
  fox.client.close();
  return { sent };
}

async function collect() {
  const [topic, end] = args;
  const fox = foxglove(url);
  const channel = await fox.channel(topic);
  const sid = fox.client.subscribe(channel.id);
  const reader = new MessageReader(rosmsg.parse(channel.schema, { ros2: true }));
  const received = [];
  while (received[received.length - 1] !== end) {
    const { message } = await fox.next(
      (e) => e.kind === "message" && e.message.subscriptionId === sid,
      `the message ${end} on ${topic}`,
    );
    const bytes = new Uint8Array(
      message.data.buffer,
      message.data.byteOffset,
      message.data.byteLength,
    );
    received.push(reader.readMessage(bytes).data);
  }
  fox.client.close();
  return { received };
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

function call(ros, name, type, request) {
  const service = new ROSLIB.Service({ ros, name, serviceType: type });
  return bounded(
    new Promise((resolve, reject) => service.callService(request, resolve, reject)),
    `the ${name} call`,
  );
}

async function play() {
  const [topic, count] = [args[0], Number(args[1])];
  const fox = foxglove(url);
  const { info } = await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const channel = await fox.channel(topic);
  const decode = reader(channel);
  const sid = fox.client.subscribe(channel.id);
  const ros = await rosbridge();
  // roslib sends each op when called: the subscription is in once a status answers a probe
  fox.ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [999999] }));
  await fox.next((e) => e.kind === "status", "the probe's status");
  await call(ros, "/rwt/player/resume", "std_srvs/srv/Trigger", {});
  const times = [];
  const messages = [];
  while (messages.length < count) {
    const event = await fox.next((e) => e.kind === "time" || e.kind === "message", "playback");
    if (event.kind === "time") times.push(event.timestamp);
    else if (event.message.subscriptionId === sid) {
      messages.push({ logTime: event.message.timestamp, data: decode.readMessage(event.message.data).data });
    }
  }
  const latest = times.reduce((a, b) => (b > a ? b : a), 0n);
  await call(ros, "/rwt/player/seek", "rwt_msgs/srv/Seek", { offset: 0.0 });
  const step = await fox.next((e) => e.kind === "time" && e.timestamp < latest, "the step back");
  const { message } = await fox.next(
    (e) => e.kind === "message" && e.message.subscriptionId === sid,
    "a message after the seek",
  );
  fox.client.close();
  ros.close();
  return {
    capabilities: info.capabilities,
    times,
    messages,
    stepBack: step.timestamp,
    afterSeek: { logTime: message.timestamp, data: decode.readMessage(message.data).data },
  };
}

async function assets() {
  const fox = foxglove(url);
  const { info } = await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  args.forEach((uri, index) => fox.client.fetchAsset(uri, index + 1));
  const responses = [];
  while (responses.length < args.length) {
    const { response } = await fox.next((e) => e.kind === "asset", "a fetchAssetResponse");
    const entry = { requestId: response.requestId, status: response.status };
    if (response.status === 0) {
      const bytes = Buffer.from(response.data.buffer, response.data.byteOffset, response.data.byteLength);
      entry.length = bytes.length;
      entry.sha256 = createHash("sha256").update(bytes).digest("hex");
    } else {
      entry.error = response.error;
    }
    responses.push(entry);
  }
  responses.sort((a, b) => a.requestId - b.requestId);
  const open = fox.ws.readyState === fox.ws.OPEN;
  fox.client.close();
  return { capabilities: info.capabilities, responses, open };
}

function sleep(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

async function callService() {
  const [service, request] = [args[0], JSON.parse(args[1])];
  const fox = foxglove(url);
  const described = await fox.service(service);
  const write = new MessageWriter(rosmsg.parse(described.request.schema, { ros2: true }));
  const read = new MessageReader(rosmsg.parse(described.response.schema, { ros2: true }));
  fox.client.sendServiceCallRequest({
    serviceId: described.id,
    callId: 1,
    encoding: "cdr",
    data: write.writeMessage(request),
  });
  const { response, failure } = await fox.next((e) => e.kind === "answer", `the answer of ${service}`);
  fox.client.close();
  return {
    type: described.type,
    schemas: [described.request.schemaName, described.response.schemaName],
    callId: (response ?? failure).callId,
    encoding: response?.encoding ?? null,
    response: response ? read.readMessage(response.data) : null,
    failure: failure?.message ?? null,
  };
}

// Ask for NAMES until every one has a value (a node's parameters are copied a while after it
// appears); at most 100 rounds, 200 ms apart.
async function readAll(fox, names) {
  for (let round = 0; round < 100; round += 1) {
    const id = `get${round}`;
    fox.client.getParameters(names, id);
    const { values } = await fox.next((e) => e.kind === "parameterValues" && e.values.id === id, id);
    if (values.parameters.length === names.length) return values.parameters;
    await sleep(200);
  }
  throw new Error(`never got ${names}`);
}

// Watch NAME, set it to VALUE (TYPE); the set's answer and the update pushed for it.
async function setWatched(fox, name, value, type) {
  fox.client.subscribeParameterUpdates([name]);
  fox.client.setParameters([{ name, value, type }], "set");
  // the answer and the update come in either order
  let set = null;
  let pushed = null;
  while (set === null || pushed === null) {
    const { values } = await fox.next(
      (e) => e.kind === "parameterValues" && (e.values.id === "set" || e.values.id === undefined),
      "the set's answer and its update",
    );
    if (values.id === "set") set = values.parameters;
    else if (values.parameters.some((p) => p.name === name)) pushed = values.parameters;
  }
  return { set, pushed };
}

async function params() {
  const [node, value] = [args[0], Number(args[1])];
  const [speed, mode] = [`${node}.speed`, `${node}.mode`];
  const fox = foxglove(url);
  const { info } = await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const read = await readAll(fox, [speed, mode]);
  const { set, pushed } = await setWatched(fox, speed, value, "float64");
  fox.client.close();
  return { capabilities: info.capabilities, read, set, pushed, statuses: fox.statuses };
}

async function param() {
  const [name, type, value] = [args[0], args[1], JSON.parse(args[2])];
  const fox = foxglove(url);
  await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const [read] = await readAll(fox, [name]);
  const { set, pushed } = await setWatched(fox, name, value, type);
  fox.client.close();
  return { read, set, pushed, statuses: fox.statuses };
}

async function watch() {
  const [name, count] = [args[0], Number(args[1])];
  const fox = foxglove(url);
  await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const [first] = await readAll(fox, [name]);
  fox.client.subscribeParameterUpdates([name]);
  const pushed = [];
  while (pushed.length < count) {
    const { values } = await fox.next(
      (e) => e.kind === "parameterValues" && e.values.id === undefined,
      `an update of ${name}`,
    );
    pushed.push(...values.parameters.filter((p) => p.name === name));
  }
  fox.client.close();
  return { first, pushed, statuses: fox.statuses };
}

async function graph() {
  const [topic] = args;
  const fox = foxglove(url);
  await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  fox.client.subscribeConnectionGraph();
  const published = new Map();
  const subscribed = new Map();
  while (!published.has(topic) || !subscribed.has(topic)) {
    const { update } = await fox.next((e) => e.kind === "graph", `the graph with ${topic}`);
    for (const t of update.publishedTopics) published.set(t.name, t.publisherIds);
    for (const t of update.subscribedTopics) subscribed.set(t.name, t.subscriberIds);
  }
  fox.client.close();
  return { publisherIds: published.get(topic), subscriberIds: subscribed.get(topic) };
}

async function robot() {
  const ros = await rosbridge();
  for (const [name, messageType] of [["/cmd_vel", "geometry_msgs/msg/Twist"], ["/tf", "tf2_msgs/msg/TFMessage"]]) {
    new ROSLIB.Topic({ ros, name, messageType }).subscribe(() => {});
  }
  const reset = new ROSLIB.Service({ ros, name: "/reset", serviceType: "std_srvs/srv/Trigger" });
  await reset.advertise((request, response) => {
    Object.assign(response, { success: true, message: "reset" });
    return true;
  });
  new ROSLIB.Topic({ ros, name: "/chatter", messageType: "std_msgs/msg/String" }).advertise();
  const fox = foxglove(url);
  await fox.channel("/chatter");
  fox.client.subscribeConnectionGraph();
  const { update } = await fox.next((e) => e.kind === "graph", "the whole connection graph");
  const ids = (entries, field) => Object.fromEntries(entries.map((e) => [e.name, e[field]]));
  const result = {
    published: ids(update.publishedTopics, "publisherIds"),
    subscribed: ids(update.subscribedTopics, "subscriberIds"),
    services: ids(update.advertisedServices, "providerIds"),
    channels: [...fox.channels.keys()],
    advertisedServices: [...fox.services.keys()],
  };
  fox.client.close();
  ros.close();
  return result;
}

await main(
  {
    receive,
    publish,
    play,
    assets,
    call: callService,
    params,
    param,
    watch,
    graph,
    robot,
    collect,
  },
  scenario,
);
