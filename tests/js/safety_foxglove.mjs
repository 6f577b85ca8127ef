#!/usr/bin/env node
// The real Foxglove client (@foxglove/ws-protocol) commanding a robot under rwt's safety
// envelope (docs/safety.md): client publish in CDR and in JSON.
//
// Usage: node safety_foxglove.mjs commands WS_URL
//   advertise /cmd_vel (geometry_msgs/msg/Twist) in cdr and in json, /arm/joint_cmd
//   (std_msgs/msg/Float64) in cdr, and /cmd_vel again as std_msgs/msg/String; send a Twist
//   out of bounds in each encoding, one with linear.x NaN (CDR carries it as is), the
//   joint at 9.0 then 1.0; report the statuses the server sent, in order.
// Stdout's last line: {"result": {...}}. Every wait is bounded.
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import { foxglove, main } from "./foxglove_client.mjs";

const { MessageWriter } = serialization;
const [scenario, url] = process.argv.slice(2);

const TWIST = `geometry_msgs/Vector3 linear
geometry_msgs/Vector3 angular
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
`;
const FLOAT64 = "float64 data\n";
const STATUSES = 4; // one clamp warning (one episode), NaN refused, 9.0 refused, String refused

function twist(x, z) {
  return { linear: { x, y: 0, z: 0 }, angular: { x: 0, y: 0, z } };
}

async function commands() {
  const fox = foxglove(url);
  await fox.next((e) => e.kind === "serverInfo", "serverInfo");
  const cdr = fox.client.advertise({
    topic: "/cmd_vel",
    encoding: "cdr",
    schemaName: "geometry_msgs/msg/Twist",
    schema: TWIST,
    schemaEncoding: "ros2msg",
  });
  const json = fox.client.advertise({
    topic: "/cmd_vel",
    encoding: "json",
    schemaName: "geometry_msgs/msg/Twist",
  });
  const joint = fox.client.advertise({
    topic: "/arm/joint_cmd",
    encoding: "cdr",
    schemaName: "std_msgs/msg/Float64",
    schema: FLOAT64,
    schemaEncoding: "ros2msg",
  });
  fox.client.advertise({ topic: "/cmd_vel", encoding: "json", schemaName: "std_msgs/msg/String" });
  const twists = new MessageWriter(rosmsg.parse(TWIST, { ros2: true }));
  const floats = new MessageWriter(rosmsg.parse(FLOAT64, { ros2: true }));
  fox.client.sendMessage(cdr, twists.writeMessage(twist(2.0, -5.0)));
  fox.client.sendMessage(json, new TextEncoder().encode(JSON.stringify(twist(3.0, 0.25))));
  fox.client.sendMessage(cdr, twists.writeMessage(twist(Number.NaN, 0.0)));
  fox.client.sendMessage(joint, floats.writeMessage({ data: 9.0 }));
  fox.client.sendMessage(joint, floats.writeMessage({ data: 1.0 }));
  const statuses = [];
  while (statuses.length < STATUSES) {
    const { status } = await fox.next((e) => e.kind === "status", `status ${statuses.length + 1}`);
    statuses.push({ level: status.level, message: status.message });
  }
  fox.client.close();
  return { statuses };
}

await main({ commands }, scenario);
