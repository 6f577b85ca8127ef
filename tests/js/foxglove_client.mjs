// A real Foxglove client (@foxglove/ws-protocol's FoxgloveClient) whose events are queued,
// so that a scenario awaits them in order. Every wait is bounded.
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
export const WAIT_MS = 15000;

export function bounded(promise, what, ms = WAIT_MS) {
  let timer;
  const timeout = new Promise((_, reject) => {
    timer = setTimeout(() => reject(new Error(`timed out waiting for ${what}`)), ms);
  });
  return Promise.race([promise, timeout]).finally(() => clearTimeout(timer));
}

// Connect to URL offering PROTOCOLS; events: serverInfo, advertise, unadvertise, status,
// message, time, asset (fetchAssetResponse), advertiseServices, unadvertiseServices, answer
// (serviceCallResponse or serviceCallFailure), parameterValues, graph
// (connectionGraphUpdate), error, close.
export function foxglove(url, protocols = ["foxglove.sdk.v1"]) {
  const ws = new WebSocket(url, protocols);
  const client = new FoxgloveClient({ ws });
  const state = {
    ws,
    client,
    channels: new Map(),
    services: new Map(),
    statuses: [],
    events: [],
    waiters: [],
  };
  const push = (event) => {
    state.events.push(event);
    for (const waiter of state.waiters.splice(0)) waiter();
  };
  client.on("serverInfo", (info) => push({ kind: "serverInfo", info }));
  client.on("advertise", (channels) => {
    for (const channel of channels) state.channels.set(channel.topic, channel);
    push({ kind: "advertise", channels });
  });
  client.on("unadvertise", (ids) => push({ kind: "unadvertise", ids }));
  client.on("status", (status) => {
    state.statuses.push(status);
    push({ kind: "status", status });
  });
  client.on("message", (message) => push({ kind: "message", message }));
  client.on("time", (time) => push({ kind: "time", timestamp: time.timestamp }));
  client.on("fetchAssetResponse", (response) => push({ kind: "asset", response }));
  client.on("advertiseServices", (services) => {
    for (const service of services) state.services.set(service.name, service);
    push({ kind: "advertiseServices", services });
  });
  client.on("unadvertiseServices", (ids) => push({ kind: "unadvertiseServices", ids }));
  client.on("serviceCallResponse", (response) => push({ kind: "answer", response }));
  client.on("serviceCallFailure", (failure) => push({ kind: "answer", failure }));
  client.on("parameterValues", (values) => push({ kind: "parameterValues", values }));
  client.on("connectionGraphUpdate", (update) => push({ kind: "graph", update }));
  client.on("error", (error) => push({ kind: "error", error: String(error) }));
  client.on("close", () => push({ kind: "close" }));
  // The next event that matches, waiting for it (and dropping the ones before it).
  state.next = (match, what) =>
    bounded(
      new Promise((resolve) => {
        const look = () => {
          while (state.events.length) {
            const event = state.events.shift();
            if (match(event)) return resolve(event);
          }
          state.waiters.push(look);
        };
        look();
      }),
      what,
    );
  state.channel = async (topic) => {
    if (!state.channels.has(topic)) {
      await state.next(
        (e) => e.kind === "advertise" && e.channels.some((c) => c.topic === topic),
        `advertise ${topic}`,
      );
    }
    return state.channels.get(topic);
  };
  state.service = async (name) => {
    if (!state.services.has(name)) {
      await state.next(
        (e) => e.kind === "advertiseServices" && e.services.some((s) => s.name === name),
        `advertiseServices ${name}`,
      );
    }
    return state.services.get(name);
  };
  return state;
}

// Run SCENARIOS[name]() and print its result as the last line: {"result": ...}.
export async function main(scenarios, name) {
  try {
    const result = await scenarios[name]();
    const text = JSON.stringify({ result }, (_, v) => (typeof v === "bigint" ? String(v) : v));
    process.stdout.write(`${text}\n`);
    process.exit(0);
  } catch (error) {
    process.stderr.write(`${error.stack ?? error}\n`);
    process.exit(1);
  }
}
