// Lichtblick's schema check, replayed against a Foxglove server with the real Foxglove client.
//
// Lichtblick (v1.28.1, its Foxglove WebSocket player) preloads its copy of the common ROS
// definitions when serverInfo names a ROS distribution (ROS 2 Humble's, or ROS 1's for
// melodic and noetic), parses every advertised ros2msg (ros1msg) schema with @lichtblick/rosmsg,
// and compares each parsed definition with the one it already holds under that name by
// @lichtblick/message-definition's isMsgDefEqual, which compares the members in order. A
// mismatch is the error alert "Definition of schema 'X' has changed during the server's
// runtime". The reference definitions are rwt's own copies, tests/foxglove/lichtblick_ros2humble.json
// and lichtblick_ros1.json: one `.msg` text a type, members in the file's order
// (docs/foxglove.md).
//
//   node lichtblick_schemas.mjs server URL DATA [TOPIC_OR_SERVICE...]
//       connect, wait for the named topics and services (then for a second of quiet), and
//       report the alerts Lichtblick's rules raise for what the server advertised
//   node lichtblick_schemas.mjs schemas SCHEMAS_JSON DATA
//       the same rule over {"pkg/msg/Type": "full text"} (a type per channel, DATA's syntax)
//   node lichtblick_schemas.mjs data SET DATA
//       compare DATA, parsed as above, with Lichtblick's own SET (ros2humble or ros1, of
//       @lichtblick/rosmsg-msgs-common)
//   node lichtblick_schemas.mjs write SET DATA
//       write DATA from Lichtblick's own SET (done once; the file is then the repository's)
import fs from "node:fs";

import { isMsgDefEqual } from "@lichtblick/message-definition";
import { parse } from "@lichtblick/rosmsg";

import { bounded, foxglove, main } from "./foxglove_client.mjs";

const QUIET_MS = 1000;
// Lichtblick's choice of preloaded set by ROS_DISTRO: galactic for foxy and galactic, ROS 1
// for melodic and noetic, humble for any other ROS 2 name.
const ROS1 = ["melodic", "noetic"];
const GALACTIC = ["foxy", "galactic"];
// The wire encodings Lichtblick calls services in, and the ones it parses ROS schemas of.
// Only cdr with ros2msg and ros1 with ros1msg (rwt's wires) are checked here; anything else
// is reported unchecked.
const SERVICE_ENCODINGS = ["json", "ros1", "cdr"];
const SCHEMA_ENCODING = { cdr: "ros2msg", ros1: "ros1msg" };
// What each of Lichtblick's sets is called and how its reference file is written.
const SETS = {
  ros2humble: {
    syntax: "ros2msg",
    source: "ROS 2 Humble's common definitions as Lichtblick v1.28.1 preloads them (@lichtblick/rosmsg-msgs-common 1.0.1, ros2humble)",
  },
  ros1: {
    syntax: "ros1msg",
    source: "ROS 1 Noetic's common definitions as Lichtblick v1.28.1 preloads them (@lichtblick/rosmsg-msgs-common 1.0.1, ros1)",
  },
};

// "pkg/Type" is also known as "pkg/msg/Type" (Lichtblick's dataTypeToFullName).
function fullName(name) {
  const parts = name.split("/");
  return parts.length === 2 ? `${parts[0]}/msg/${parts[1]}` : name;
}

// A schema's datatypes as Lichtblick's parseChannel gives them: the first definition under the
// schema's name, each later one under its MSG: name.
function datatypes(schemaName, text, syntax) {
  const map = new Map();
  parse(text, { ros2: syntax === "ros2msg" }).forEach(({ name, definitions }, index) => {
    if (index === 0) map.set(schemaName, { name: schemaName, definitions });
    else if (name !== undefined) map.set(name, { name, definitions });
  });
  return map;
}

// The reference file's types, parsed one by one as Lichtblick holds them, and their syntax.
function reference(path) {
  const data = JSON.parse(fs.readFileSync(path, "utf8"));
  const map = new Map();
  for (const [name, text] of Object.entries(data.types)) {
    const ros2 = data.syntax === "ros2msg";
    const [definition] = parse(text, { ros2, skipTypeFixup: true });
    map.set(name, { name, definitions: definition.definitions });
  }
  return { syntax: data.syntax, types: map };
}

// Lichtblick's datatype bookkeeping and the alerts it raises, keyed as it keys them.
class Player {
  constructor() {
    this.known = new Map();
    this.alerts = new Map();
    this.compared = new Set(); // names met again, whether equal or not
  }

  alert(id, severity, message) {
    this.alerts.set(id, { id, severity, message });
  }

  update(types) {
    for (const [name, definition] of types) {
      const known = this.known.get(name);
      if (known !== undefined) this.compared.add(name);
      if (known !== undefined && !isMsgDefEqual(definition, known)) {
        this.alert(
          `schema-changed-${name}`,
          "error",
          `Definition of schema '${name}' has changed during the server's runtime`,
        );
        continue;
      }
      this.known.set(name, definition);
      const full = fullName(name);
      if (full !== name) {
        const renamed = definition.name ? fullName(definition.name) : undefined;
        this.known.set(full, { ...definition, name: renamed });
      }
    }
  }

  channel(channel, seen) {
    const syntax = SCHEMA_ENCODING[channel.encoding];
    if (syntax === undefined || (channel.schemaEncoding ?? syntax) !== syntax) {
      this.alert(`unchecked:${channel.topic}`, "error", `not checked: ${channel.encoding}`);
      return;
    }
    let types;
    try {
      types = datatypes(channel.schemaName, channel.schema, syntax);
    } catch (error) {
      this.alert(`schema:${channel.topic}`, "error", `Failed to parse channel schema: ${error}`);
      return;
    }
    const earlier = seen.get(channel.topic);
    if (earlier !== undefined && JSON.stringify(earlier) !== JSON.stringify(channel)) {
      this.alert(`duplicate-topic:${channel.topic}`, "error", "Multiple channels advertise it");
      return;
    }
    seen.set(channel.topic, channel);
    this.update(types);
  }

  service(service, defaultEncoding) {
    const parts = [service.request, service.response];
    if (parts.some((part) => part === undefined)) {
      this.alert(`service:${service.id}`, "error", "Invalid service definition");
      return;
    }
    if (service.requestSchema !== undefined || service.responseSchema !== undefined) {
      this.alert(`service:${service.id}`, "warn", "requestSchema/responseSchema are deprecated");
    }
    for (const part of parts) {
      const encoding = part.encoding ?? defaultEncoding;
      const syntax = SCHEMA_ENCODING[encoding];
      if (syntax === undefined) {
        this.alert(`unchecked:${service.name}`, "error", `not checked: ${encoding}`);
        return;
      }
      try {
        this.update(datatypes(part.schemaName, part.schema, syntax));
      } catch (error) {
        this.alert(`service:${service.id}`, "error", `Failed to parse service: ${error}`);
        return;
      }
    }
  }
}

function distroCheck(player, metadata, path) {
  const distro = metadata?.ROS_DISTRO;
  if (!distro) return "none";
  const { syntax, types } = reference(path);
  const wanted = ROS1.includes(distro) ? "ros1msg" : "ros2msg";
  if (GALACTIC.includes(distro) || syntax !== wanted) {
    player.alert("reference", "error", `${path} is not ${distro}'s preloaded set`);
    return distro;
  }
  player.update(types);
  return distro;
}

function report(player, extra) {
  return {
    ...extra,
    compared: [...player.compared].sort(),
    alerts: [...player.alerts.values()],
  };
}

async function server(url, path, ...names) {
  const fx = foxglove(url);
  const info = await fx.next((e) => e.kind === "serverInfo", "serverInfo");
  for (const name of names) {
    await bounded(
      new Promise((resolve) => {
        const look = () =>
          fx.channels.has(name) || fx.services.has(name) ? resolve() : setTimeout(look, 50);
        look();
      }),
      `advertisement of ${name}`,
    );
  }
  // then wait for a second without news: advertisements come in several frames
  let count = -1;
  while (count !== fx.channels.size + fx.services.size + fx.statuses.length) {
    count = fx.channels.size + fx.services.size + fx.statuses.length;
    await new Promise((resolve) => setTimeout(resolve, QUIET_MS));
  }
  fx.ws.close();
  const player = new Player();
  const { capabilities, supportedEncodings, metadata } = info.info;
  if (!Array.isArray(capabilities)) player.alert("ws:invalid-capabilities", "warn", "capabilities");
  const distro = distroCheck(player, metadata, path);
  const seen = new Map();
  for (const channel of fx.channels.values()) player.channel(channel, seen);
  if (capabilities.includes("services")) {
    const encoding = supportedEncodings?.find((e) => SERVICE_ENCODINGS.includes(e));
    if (encoding === undefined) player.alert("callService:unsupportedEncoding", "warn", "none");
    for (const service of fx.services.values()) player.service(service, encoding);
  }
  const levels = ["info", "warn", "error"];
  for (const status of fx.statuses) player.alert(status.message, levels[status.level], "status");
  return report(player, {
    distro,
    channels: [...fx.channels.keys()].sort(),
    services: [...fx.services.keys()].sort(),
  });
}

function schemas(schemasPath, path) {
  const player = new Player();
  const { syntax, types } = reference(path);
  player.update(types);
  const encoding = syntax === "ros2msg" ? "cdr" : "ros1";
  const texts = JSON.parse(fs.readFileSync(schemasPath, "utf8"));
  const seen = new Map();
  for (const [name, text] of Object.entries(texts)) {
    const channel = { topic: name, encoding, schemaName: name, schema: text };
    player.channel({ ...channel, schemaEncoding: syntax }, seen);
  }
  return report(player, { types: Object.keys(texts).length });
}

async function lichtblickSet(set) {
  const { default: common } = await import("@lichtblick/rosmsg-msgs-common");
  if (!(set in SETS)) throw new Error(`no set ${set}: ${Object.keys(SETS)}`);
  return common[set];
}

async function data(set, path) {
  const own = reference(path).types;
  const theirs = await lichtblickSet(set);
  const unequal = Object.keys(theirs).filter(
    (name) => !own.has(name) || !isMsgDefEqual(own.get(name), theirs[name]),
  );
  const extra = [...own.keys()].filter((name) => !(name in theirs));
  return { types: own.size, unequal, extra };
}

// One member as a `.msg` line that @lichtblick/rosmsg parses back to the same member.
function literal(value) {
  if (Array.isArray(value)) return `[${value.map(literal).join(", ")}]`;
  if (typeof value === "string") return JSON.stringify(value);
  return String(value);
}

function line(member, syntax) {
  const ros2 = { time: "builtin_interfaces/Time", duration: "builtin_interfaces/Duration" };
  let text = (syntax === "ros2msg" ? ros2[member.type] : undefined) ?? member.type;
  if (member.upperBound !== undefined) text += `<=${member.upperBound}`;
  if (member.arrayLength !== undefined) text += `[${member.arrayLength}]`;
  else if (member.arrayUpperBound !== undefined) text += `[<=${member.arrayUpperBound}]`;
  else if (member.isArray) text += "[]";
  text += ` ${member.name}`;
  if (member.isConstant) return `${text}=${member.valueText}`;
  if (member.defaultValue !== undefined) text += ` ${literal(member.defaultValue)}`;
  return text;
}

async function write(set, path) {
  const theirs = await lichtblickSet(set);
  const { syntax, source } = SETS[set];
  const types = {};
  for (const name of Object.keys(theirs).sort()) {
    types[name] = theirs[name].definitions.map((member) => line(member, syntax)).join("\n");
  }
  const lines = Object.entries(types).map(([k, v]) => `${JSON.stringify(k)}: ${JSON.stringify(v)}`);
  const head = `{"source": ${JSON.stringify(source)}, "syntax": ${JSON.stringify(syntax)}`;
  const text = `${head}, "types": {\n${lines.join(",\n")}\n}}\n`;
  fs.writeFileSync(path, text);
  return { types: Object.keys(types).length };
}

const [name, ...args] = process.argv.slice(2);
const SCENARIOS = {
  server: () => server(...args),
  schemas: () => schemas(...args),
  data: () => data(...args),
  write: () => write(...args),
};
main(SCENARIOS, name);
