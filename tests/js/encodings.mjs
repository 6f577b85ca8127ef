#!/usr/bin/env node
// Drive the real roslib (roslibjs 2.x) through the encodings of docs/decisions.md: cbor and
// png subscriptions, a fragmented service response, a publish sent as fragments.
//
// Usage: node encodings.mjs WS_URL SPEC.json
//
// SPEC: {
//   "connections": [{
//     "name": "a",
//     "subscribe": [{"topic", "type", "compression"?}],        // roslib Topic options
//     "call": [{"service", "type", "args", "fragment_size"}],  // roslib Service.callService
//     "publish_fragments": [{"topic", "type", "msg", "fragment_size"}]
//   }],
//   "ready": {"topic", "type"},   // each connection publishes {data: name} once subscribed
//   "expect": {"<conn>:<topic>": count}
// }
// roslib's Service does not send fragment_size, so the test adds it to the
// call_service op on its way out (ros.callOnConnection); reassembly of the reply
// is roslib's own. roslib cannot fragment what it sends, so publish_fragments
// splits the publish op's JSON text here and sends each fragment op through roslib.
//
// Stdout: one line {"received": {"<conn>:<topic>": [msg, ...]}, "calls": {...}}
// where typed arrays are {"$type", "length", "values" (<= 64 elements), "sha256"}
// and strings over 256 characters are {"$type": "string", "length", "sha256"}.
// Exit codes: 0 done, 2 failed or timed out, 64 bad usage. Every wait is bounded.
import { createHash } from "node:crypto";
import { readFileSync } from "node:fs";
import * as ROSLIB from "roslib";

function die(code, message) {
  process.stderr.write(`encodings.mjs: ${message}\n`);
  process.exit(code);
}

const [url, specPath] = process.argv.slice(2);
if (!url || !specPath) die(64, "usage: node encodings.mjs WS_URL SPEC.json");
const spec = JSON.parse(readFileSync(specPath, "utf8"));
setTimeout(() => die(2, `timed out; state: ${JSON.stringify(summary())}`), spec.timeout_ms ?? 30000).unref();

function sha256(bytes) {
  return createHash("sha256").update(bytes).digest("hex");
}

function describe(value) {
  if (ArrayBuffer.isView(value)) {
    const bytes = new Uint8Array(value.buffer, value.byteOffset, value.byteLength);
    const out = { $type: value.constructor.name, length: value.length, sha256: sha256(bytes) };
    if (value.length <= 64) out.values = Array.from(value, (v) => (typeof v === "bigint" ? v.toString() : v));
    return out;
  }
  if (typeof value === "string" && value.length > 256) {
    return { $type: "string", length: value.length, sha256: sha256(Buffer.from(value, "utf8")) };
  }
  if (typeof value === "bigint") return { $type: "bigint", value: value.toString() };
  if (Array.isArray(value)) return value.map(describe);
  if (value && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, describe(v)]));
  }
  return value;
}

const received = {};
const calls = {};
const waiters = new Set();
function notify() {
  for (const w of waiters) if (w()) waiters.delete(w);
}
function summary() {
  return Object.fromEntries(Object.entries(received).map(([k, v]) => [k, v.length]));
}
function until(predicate) {
  return new Promise((resolve) => {
    const check = () => (predicate() ? (resolve(), true) : false);
    if (!check()) waiters.add(check);
  });
}

async function connect() {
  const ros = new ROSLIB.Ros({});
  const opened = new Promise((resolve, reject) => {
    ros.once("connection", resolve);
    ros.once("error", (e) => reject(new Error(`connection error: ${e?.message ?? e}`)));
  });
  await ros.connect(url);
  await opened;
  return ros;
}

function withFragmentSize(ros, size) {
  const send = ros.callOnConnection.bind(ros);
  ros.callOnConnection = (message) =>
    send(message.op === "call_service" ? { ...message, fragment_size: size } : message);
}

function publishAsFragments(ros, step, index) {
  const topic = new ROSLIB.Topic({ ros, name: step.topic, messageType: step.type });
  topic.advertise();
  const text = JSON.stringify({ op: "publish", topic: step.topic, msg: step.msg });
  const total = Math.ceil(text.length / step.fragment_size);
  const id = `big:${process.pid}:${index}`;
  for (let num = total - 1; num >= 0; num--) {
    // Sent last part first: the server reassembles by num, in any order.
    const data = text.slice(num * step.fragment_size, (num + 1) * step.fragment_size);
    ros.callOnConnection({ op: "fragment", id, data, num, total });
  }
}

async function main() {
  const conns = [];
  for (const c of spec.connections) conns.push({ spec: c, ros: await connect() });
  for (const { spec: c, ros } of conns) {
    for (const s of c.subscribe ?? []) {
      const key = `${c.name}:${s.topic}`;
      received[key] = [];
      const topic = new ROSLIB.Topic({ ros, name: s.topic, messageType: s.type, compression: s.compression ?? "none" });
      topic.subscribe((msg) => {
        received[key].push(describe(msg));
        notify();
      });
    }
  }
  for (const { spec: c, ros } of conns) {
    if (spec.ready) {
      const ready = new ROSLIB.Topic({ ros, name: spec.ready.topic, messageType: spec.ready.type });
      ready.publish({ data: c.name });
    }
    (c.publish_fragments ?? []).forEach((step, i) => publishAsFragments(ros, step, i));
    for (const call of c.call ?? []) {
      const key = `${c.name}:${call.service}`;
      if (call.fragment_size) withFragmentSize(ros, call.fragment_size);
      const service = new ROSLIB.Service({ ros, name: call.service, serviceType: call.type });
      service.callService(
        call.args ?? {},
        (values) => {
          calls[key] = { result: true, values: describe(values) };
          notify();
        },
        (error) => {
          calls[key] = { result: false, values: describe(error) };
          notify();
        },
      );
    }
  }
  await until(() => {
    const topicsDone = Object.entries(spec.expect ?? {}).every(([k, n]) => (received[k] ?? []).length >= n);
    const callsDone = conns.every(({ spec: c }) => (c.call ?? []).every((call) => `${c.name}:${call.service}` in calls));
    return topicsDone && callsDone;
  });
  await new Promise((resolve) => process.stdout.write(JSON.stringify({ received, calls }) + "\n", resolve));
  for (const { ros } of conns) ros.close();
  process.exit(0);
}

main().catch((e) => die(2, `failed: ${e?.stack ?? e}`));
