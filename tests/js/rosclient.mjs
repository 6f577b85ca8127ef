#!/usr/bin/env node
// Run one client scenario with the real, unmodified roslib (roslibjs 2.x) in Node.
//
// Usage: node rosclient.mjs WS_URL SCENARIO.json
//
// This is the Node twin of tests/integration/roslibpy_driver.py; both read the same
// scenario format (tests/integration/client_harness.py writes the files and reads
// the output; the docstring of roslibpy_driver.py describes the steps).
//
// roslib 2.x picks its transport at connect time: the global WebSocket when there
// is one (browsers, Node >= 22), otherwise it imports the `ws` package itself
// (Node 20), so nothing has to be put on globalThis here.
//
// Stdout: {"event": NAME} lines for `signal` steps, then one final line
// {"result": {"received": {conn: {topic: [msg, ...]}}, "wire": {...},
//             "status_count": n, "statuses": [frame, ...], "calls": {AS: {ok|error}},
//             "served": {conn: {name: [args, ...]}}, "feedback": {AS: [values, ...]},
//             "goal_ids": {AS: id}, "order": {conn: [AS, ...]}}}.
// Services use roslib's Service (advertise / advertiseAsync / callService),
// actions its ROS 2 Action (advertise + sendFeedback / setSucceeded /
// setCanceled / setFailed; sendGoal / cancelGoal).
// Exit codes: 0 done, 2 a step failed or timed out, 3 the whole scenario timed
// out, 64 bad usage. Every wait is bounded.
import { readFileSync } from "node:fs";
import { createInterface } from "node:readline";
import * as ROSLIB from "roslib";

function die(code, message) {
  process.stderr.write(`rosclient.mjs: ${message}\n`);
  process.exit(code);
}

const [url, scenarioPath] = process.argv.slice(2);
if (!url || !scenarioPath) die(64, "usage: node rosclient.mjs WS_URL SCENARIO.json");
const scenario = JSON.parse(readFileSync(scenarioPath, "utf8"));
const stepTimeoutMs = scenario.step_timeout_ms ?? 10000;
const overallMs = scenario.timeout_ms ?? 30000;

let current = "start";
setTimeout(
  () => die(3, `scenario timed out after ${overallMs} ms at step ${current}`),
  overallMs,
).unref();

// --- waiting: every arrival re-checks the pending predicates -----------------
const waiters = new Set();
function notify() {
  for (const w of waiters) {
    if (w.predicate()) {
      waiters.delete(w);
      clearTimeout(w.timer);
      w.resolve();
    }
  }
}
function until(predicate, what) {
  if (predicate()) return Promise.resolve();
  return new Promise((resolve, reject) => {
    const w = { predicate, resolve };
    w.timer = setTimeout(() => {
      waiters.delete(w);
      reject(new Error(`timed out after ${stepTimeoutMs} ms waiting for ${what()}`));
    }, stepTimeoutMs);
    waiters.add(w);
  });
}

// --- stdin lines for `await` ------------------------------------------------
let stdinLines = null;
const pendingLines = [];
let lineWaiter = null;
let stdinClosed = false;
function nextLine() {
  if (stdinLines === null) {
    stdinLines = createInterface({ input: process.stdin });
    stdinLines.on("line", (line) => {
      if (lineWaiter) {
        const w = lineWaiter;
        lineWaiter = null;
        w.resolve(line);
      } else pendingLines.push(line);
    });
    stdinLines.on("close", () => {
      stdinClosed = true;
      if (lineWaiter) lineWaiter.reject(new Error("stdin closed while awaiting the go-ahead"));
    });
  }
  if (pendingLines.length) return Promise.resolve(pendingLines.shift());
  if (stdinClosed) return Promise.reject(new Error("stdin closed while awaiting the go-ahead"));
  return new Promise((resolve, reject) => {
    lineWaiter = { resolve, reject };
  });
}

// --- connections ------------------------------------------------------------
const conns = new Map();
const statuses = [];
const calls = {};
const tfs = {};
const order = {};
const feedback = {};
const goals = new Map();

// The `reply` rules of `advertise_service` that compute a response (the same as
// in roslibpy_driver.py and serve_fixture.py).
const REPLIES = {
  set_bool: (r) => ({ success: r.data, message: r.data ? "on" : "off" }),
  trigger: () => ({ success: true, message: "triggered" }),
  empty: () => ({}),
  add: (r) => ({ sum: r.a + r.b }),
  scale: (r) => ({
    points: r.points.map((p) => ({ x: p.x * r.factor, y: p.y * r.factor })),
    note: `${r.points.length} points`,
  }),
};
// Fibonacci goals from this order on wait for a cancel.
const HOLD_ORDER = 100;

function finish(c, name, outcome) {
  calls[name] = outcome;
  (order[c.name] ??= []).push(name);
  notify();
}

function untilCalls(names) {
  return until(
    () => names.every((n) => n in calls),
    () => `${JSON.stringify(names.filter((n) => !(n in calls)))} to end`,
  );
}

function served(c, name, args) {
  (c.served[name] ??= []).push(args);
  notify();
}

function conn(step) {
  const c = conns.get(step.conn);
  if (!c) throw new Error(`connection ${JSON.stringify(step.conn)} was never opened`);
  return c;
}

function topic(c, name, type, typeless = false, compression = undefined) {
  if (!c.topics.has(name)) {
    if (!type && !typeless) throw new Error(`topic ${name} needs a type on first use`);
    c.topics.set(name, new ROSLIB.Topic({ ros: c.ros, name, messageType: type, compression }));
  }
  return c.topics.get(name);
}

function record(store, name, msg) {
  if (!store[name]) store[name] = [];
  store[name].push(msg);
  notify();
}

const steps = {
  async connect(step) {
    const ros = new ROSLIB.Ros({});
    const opened = new Promise((resolve, reject) => {
      ros.once("connection", resolve);
      ros.once("error", (e) => reject(new Error(`connection error: ${e?.message ?? e}`)));
      ros.once("close", () => reject(new Error("connection closed before it opened")));
    });
    const timer = new Promise((_, reject) => {
      setTimeout(
        () => reject(new Error(`could not connect ${step.conn} to ${url} in ${stepTimeoutMs} ms`)),
        stepTimeoutMs,
      ).unref();
    });
    await ros.connect(url);
    await Promise.race([opened, timer]);
    // Status frames are not routed to user code unless one listens for
    // "status:<id>" with roslib's own generated ids; collect them from the
    // transport for the report.
    ros.transport.on("message", (m) => {
      if (m && m.op === "status") {
        statuses.push({ conn: step.conn, ...m });
        notify();
      }
    });
    const c = {
      name: step.conn,
      ros,
      topics: new Map(),
      received: {},
      wire: {},
      wireListeners: new Set(),
      syncCounter: 0,
      syncSeen: new Set(),
      closed: false,
      served: {},
      services: new Map(),
      actions: new Map(),
    };
    ros.on("close", () => {
      c.closed = true;
      notify();
    });
    conns.set(step.conn, c);
  },

  async advertise(step) {
    topic(conn(step), step.topic, step.type).advertise();
  },

  async subscribe(step) {
    const c = conn(step);
    const name = step.topic;
    if (!c.received[name]) c.received[name] = [];
    if (!c.wire[name]) c.wire[name] = [];
    if (!c.wireListeners.has(name)) {
      // Every publish frame for this topic name, also after unsubscribe.
      c.ros.on(name, (frame) => record(c.wire, name, frame.msg));
      c.wireListeners.add(name);
    }
    // A subscribe step may leave the type out (the server knows the topic):
    // roslib then sends no "type" at all.
    // "compression" ("png", "cbor") is roslib's Topic option, sent with the subscribe.
    topic(c, name, step.type, true, step.compression).subscribe((msg) =>
      record(c.received, name, msg),
    );
  },

  async unsubscribe(step) {
    conn(step).topics.get(step.topic).unsubscribe();
  },

  async publish(step) {
    const t = topic(conn(step), step.topic, step.type);
    const msgs = step.msgs ?? [step.msg];
    for (const m of msgs) t.publish(m);
  },

  async sync(step) {
    const c = conn(step);
    const name = `/rwt_test_sync/${c.name}`;
    if (!c.topics.has(name)) {
      const t = new ROSLIB.Topic({ ros: c.ros, name, messageType: "std_msgs/String" });
      c.topics.set(name, t);
      t.subscribe((msg) => {
        c.syncSeen.add(msg.data);
        notify();
      });
      t.advertise();
    }
    c.syncCounter += 1;
    const token = `${c.name}:${process.pid}:${c.syncCounter}`;
    c.topics.get(name).publish({ data: token });
    await until(
      () => c.syncSeen.has(token),
      () => `sync token ${token} to come back on ${name} (${c.name})`,
    );
  },

  async wait(step) {
    const c = conn(step);
    const got = () => (c.received[step.topic] ?? []).length;
    await until(
      () => got() >= step.count,
      () => `${step.count} messages on ${step.topic} at ${c.name} (got ${got()})`,
    );
  },

  async api(step) {
    // A rosapi helper of Ros (getTopics...) or of Param (Param.get/set/delete, the
    // parameter name first): record what its callback or failure callback got.
    const c = conn(step);
    const args = step.args ?? [];
    let target = c.ros;
    let method = step.call;
    if (method.startsWith("Param.")) {
      target = new ROSLIB.Param({ ros: c.ros, name: args.shift() });
      method = method.slice("Param.".length);
    }
    if (typeof target[method] !== "function") throw new Error(`no method ${step.call}`);
    let done = false;
    target[method](
      ...args,
      (value) => {
        calls[step.as] = { ok: value ?? null };
        done = true;
        notify();
      },
      (error) => {
        calls[step.as] = { error: String(error?.message ?? error) };
        done = true;
        notify();
      },
    );
    await until(
      () => done,
      () => `${step.call} to answer (${c.name})`,
    );
  },

  async tf(step) {
    // A TF client of roslib subscribed to step.frames; see roslibpy_driver.py.
    const c = conn(step);
    const options = {
      ros: c.ros,
      fixedFrame: step.fixed_frame,
      angularThres: step.angular_thres,
      transThres: step.trans_thres,
      rate: step.rate,
    };
    let client;
    if (step.client === "ROS2TFClient") client = new ROSLIB.ROS2TFClient(options);
    else if (step.client === "TFClient") client = new ROSLIB.TFClient(options);
    else if (step.client === "TFClient+service") {
      // Its actionlib goal is never sent (the update is delayed for ever); the
      // transforms come through processResponse, as in older roslibjs's non-groovy mode.
      client = new ROSLIB.TFClient({ ...options, updateDelay: 2 ** 31 - 1 });
    } else throw new Error(`no TF client ${step.client}`);
    const got = {};
    for (const frame of step.frames) {
      got[frame] = [];
      client.subscribe(frame, (t) => {
        got[frame].push({ translation: { ...t.translation }, rotation: { ...t.rotation } });
        notify();
      });
    }
    tfs[step.as] = { client, got };
    if (step.client === "TFClient+service") {
      const service = new ROSLIB.Service({
        ros: c.ros,
        name: "/republish_tfs",
        serviceType: "tf2_web_republisher/RepublishTFs",
      });
      const request = {
        source_frames: Object.keys(client.frameInfos),
        target_frame: client.fixedFrame,
        angular_thres: client.angularThres,
        trans_thres: client.transThres,
        rate: client.rate,
        timeout: client.topicTimeout,
      };
      let answered = false;
      service.callService(
        request,
        (response) => {
          client.processResponse(response);
          answered = true;
          notify();
        },
        (error) => {
          calls[step.as] = { error: String(error) };
          answered = true;
          notify();
        },
      );
      await until(
        () => answered,
        () => `/republish_tfs to answer (${c.name})`,
      );
    }
  },

  async tf_wait(step) {
    const got = tfs[step.as].got[step.frame];
    await until(
      () => got.length >= step.count,
      () => `${step.count} transforms of ${step.frame} (${step.as}, got ${got.length})`,
    );
  },

  async tf_dispose(step) {
    tfs[step.as].client.dispose();
  },

  async advertise_service(step) {
    const c = conn(step);
    const name = step.service;
    const service = new ROSLIB.Service({ ros: c.ros, name, serviceType: step.type });
    c.served[name] ??= [];
    const rule = REPLIES[step.reply];
    if (rule) {
      // The classic form: fill in the response object, return true.
      await service.advertise((request, response) => {
        served(c, name, request);
        Object.assign(response, rule(request));
        return true;
      });
    } else if (step.reply === "refuse") {
      await service.advertiseAsync(async (request) => {
        served(c, name, request);
        throw new Error("refused");
      });
    } else if (step.reply === "hold") {
      await service.advertiseAsync((request) => {
        served(c, name, request);
        return new Promise(() => {}); // never answered: the test kills this process
      });
    } else if (step.reply === "gather") {
      const held = [];
      await service.advertiseAsync((request) => {
        served(c, name, request);
        return new Promise((resolve) => {
          held.push(() => resolve(REPLIES.add(request)));
          // All there: resolve newest first; roslib sends each response in the
          // order its promise resolved. Wait a microtask, so that roslib awaits
          // this last promise before it is resolved, like the others.
          if (held.length === step.count) {
            queueMicrotask(() => {
              for (const answer of held.splice(0).reverse()) answer();
            });
          }
        });
      });
    } else throw new Error(`unknown reply rule ${JSON.stringify(step.reply)}`);
    c.services.set(name, service);
  },

  async call(step) {
    const c = conn(step);
    const service = new ROSLIB.Service({ ros: c.ros, name: step.service, serviceType: step.type });
    const name = step.as;
    service.callService(
      step.args ?? {},
      (values) => finish(c, name, { ok: values ?? null }),
      (error) => finish(c, name, { error: String(error?.message ?? error) }),
    );
    if (step.wait !== false) await untilCalls([name]);
  },

  async wait_calls(step) {
    await untilCalls(step.as);
  },

  async wait_served(step) {
    const c = conn(step);
    const got = () => (c.served[step.service] ?? []).length;
    await until(
      () => got() >= step.count,
      () => `${step.count} requests for ${step.service} at ${c.name} (got ${got()})`,
    );
  },

  async advertise_action(step) {
    const c = conn(step);
    const name = step.action;
    const action = new ROSLIB.Action({ ros: c.ros, name, actionType: step.type });
    c.served[name] ??= [];
    const held = new Map(); // goal id -> sequence so far, for goals waiting for a cancel
    action.advertise(
      (goal, id) => {
        served(c, name, goal);
        if (goal.order < 0) {
          action.setFailed(id);
          return;
        }
        const sequence = [0, 1];
        if (goal.order >= HOLD_ORDER) {
          held.set(id, sequence);
          action.sendFeedback(id, { sequence });
          return;
        }
        for (let i = 1; i < goal.order; i++) {
          sequence.push(sequence.at(-1) + sequence.at(-2));
          action.sendFeedback(id, { sequence: [...sequence] });
        }
        action.setSucceeded(id, { sequence });
      },
      (id) => {
        const sequence = held.get(id);
        if (sequence === undefined) return;
        held.delete(id);
        action.setCanceled(id, { sequence });
      },
    );
    c.actions.set(name, action);
  },

  async send_goal(step) {
    const c = conn(step);
    const action = new ROSLIB.Action({ ros: c.ros, name: step.action, actionType: step.type });
    const name = step.as;
    feedback[name] = [];
    const id = action.sendGoal(
      step.args,
      (result) => finish(c, name, { ok: result ?? null }),
      (values) => {
        feedback[name].push(values);
        notify();
      },
      (error) => finish(c, name, { error: String(error) }),
    );
    goals.set(name, { action, id });
    if (step.wait !== false) await untilCalls([name]);
  },

  async wait_feedback(step) {
    const got = () => (feedback[step.as] ?? []).length;
    await until(
      () => got() >= step.count,
      () => `${step.count} feedback messages for ${step.as} (got ${got()})`,
    );
  },

  async cancel_goal(step) {
    const goal = goals.get(step.as);
    if (!goal) throw new Error(`no goal sent as ${step.as}`);
    goal.action.cancelGoal(goal.id);
  },

  async quiet(step) {
    // A bounded window for negative assertions ("nothing more arrives").
    await new Promise((resolve) => setTimeout(resolve, step.ms));
  },

  async signal(step) {
    process.stdout.write(JSON.stringify({ event: step.name }) + "\n");
  },

  async await() {
    await nextLine();
  },

  async close(step) {
    const c = conn(step);
    c.ros.close();
    await until(
      () => c.closed,
      () => `connection ${c.name} to close`,
    );
  },
};

async function main() {
  for (const [index, step] of scenario.steps.entries()) {
    current = `#${index} ${JSON.stringify(step).slice(0, 200)}`;
    const handler = steps[step.op];
    if (!handler) die(64, `unknown step op ${JSON.stringify(step.op)}`);
    await handler(step);
  }
  const received = {};
  const wire = {};
  const servedBy = {};
  for (const c of conns.values()) {
    received[c.name] = c.received;
    wire[c.name] = c.wire;
    servedBy[c.name] = c.served;
  }
  const tf = Object.fromEntries(Object.entries(tfs).map(([name, t]) => [name, t.got]));
  const goalIds = Object.fromEntries([...goals].map(([name, goal]) => [name, goal.id]));
  const result = {
    received,
    wire,
    status_count: statuses.length,
    statuses,
    calls,
    served: servedBy,
    feedback,
    goal_ids: goalIds,
    order,
    tf,
  };
  // Wait for the write to be flushed: a large result on a pipe is written in
  // pieces, and process.exit() would cut it.
  await new Promise((resolve) => process.stdout.write(JSON.stringify({ result }) + "\n", resolve));
  // Close what is still open (bounded), then leave.
  const open = [...conns.values()].filter((c) => !c.closed);
  for (const c of open) c.ros.close();
  try {
    await until(
      () => open.every((c) => c.closed),
      () => "connections to close",
    );
  } catch (e) {
    process.stderr.write(`rosclient.mjs: ${e.message}\n`);
  }
  process.exit(0);
}

main().catch((e) => die(2, `step ${current} failed: ${e?.stack ?? e}`));
