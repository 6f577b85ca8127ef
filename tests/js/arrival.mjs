#!/usr/bin/env node
// Subscribe on one roslib connection, publish from another: does the subscriber
// get the message? The pattern of every roslibjs test suite that checks a topic.
//
// Usage: node arrival.mjs WS_URL ROUNDS
//
// Each round opens two new ROSLIB.Ros connections. Once both are open, the
// subscriber subscribes (throttle_rate and queue_length set, as roslibjs's own
// topic tests do), and right after that the publisher advertises and publishes
// one message (roslib sends advertise and publish back to back). roslib writes
// each frame when it is called, so the subscribe reached the server first.
// Stdout: one line {"rounds": N, "missed": [round, ...]}. Every wait is bounded.
import * as ROSLIB from "roslib";

const [url, roundsText] = process.argv.slice(2);
const rounds = Number(roundsText);
if (!url || !(rounds > 0)) {
  process.stderr.write("usage: node arrival.mjs WS_URL ROUNDS\n");
  process.exit(64);
}
const WAIT_MS = 2000; // a message that was missed never comes

function open() {
  return new Promise((resolve, reject) => {
    const ros = new ROSLIB.Ros({ url });
    const timer = setTimeout(() => reject(new Error("connect timed out")), 10000);
    ros.on("connection", () => {
      clearTimeout(timer);
      resolve(ros);
    });
    ros.on("error", (error) => reject(new Error(`connection error: ${error}`)));
  });
}

const missed = [];
for (let index = 0; index < rounds; index += 1) {
  const [sub, pub] = await Promise.all([open(), open()]);
  const name = `/arrival_js_${index}`;
  const messageType = "std_msgs/msg/String";
  const listener = new ROSLIB.Topic({
    ros: sub, name, messageType, throttle_rate: 100, queue_length: 5,
  });
  const talker = new ROSLIB.Topic({ ros: pub, name, messageType });
  const got = new Promise((resolve) => {
    const timer = setTimeout(() => resolve(false), WAIT_MS);
    listener.subscribe((message) => {
      if (message.data === `m${index}`) {
        clearTimeout(timer);
        resolve(true);
      }
    });
  });
  talker.publish({ data: `m${index}` });
  if (!(await got)) missed.push(index);
  sub.close();
  pub.close();
}
process.stdout.write(`${JSON.stringify({ rounds, missed })}\n`);
process.exit(0);
