// roslib over WebRTC: a transport factory for `rwt serve --webrtc` (docs/webrtc.md).
//
// Served by rwt at /webrtc/roslib-transport.js, on the port that answers the offers.
// Plain JavaScript, no build step and no dependency: pass roslib's AbstractTransport in.
//
//   import { Ros, AbstractTransport } from "roslib";
//   import { webrtcTransportFactory } from "http://robot.local:9090/webrtc/roslib-transport.js";
//   const ros = new Ros({
//     url: "http://robot.local:9090",
//     transportFactory: webrtcTransportFactory(AbstractTransport, { lossyTopics: ["/pose"] }),
//   });
//
// Options: lossyTopics, topics whose subscriptions go on the `rosbridge-lossy` channel
// (latest-only, unordered, a lost message sent again once at most: D36, D73); token, a
// video token sent as `Authorization: Bearer` with the offer; rtcConfiguration, for
// RTCPeerConnection.

// One retransmission, not none (D73): with none, each lost packet leaves a gap that only
// a FORWARD TSN closes, one a round trip in libwebrtc's SCTP; a browser's SACK reports 20
// gaps, so on a lossy link a fast topic's gaps pile up and the channel stalls for seconds.
const LOSSY = { ordered: false, maxRetransmits: 1 };
// A subscribe sent on the lossy channel is itself not reliable: lost on the way (twice),
// the subscription would deliver nothing. So it is sent again after each of these
// delays (ms) until its topic's first message comes on the lossy channel, or it is
// unsubscribed (the server takes a subscribe of the same id again as the same one).
const RESEND_MS = [200, 400, 800, 1600, 3200, 3200, 3200, 3200];

export function webrtcTransportFactory(AbstractTransport, options = {}) {
  const { lossyTopics = [], token = null, rtcConfiguration = {} } = options;
  const lossy = new Set(lossyTopics);

  class DataChannelTransport extends AbstractTransport {
    constructor(pc, channel, lossyChannel, session) {
      super();
      Object.assign(this, { pc, channel, lossyChannel, session });
      this.unconfirmed = new Map();  // topic -> timer of a lossy subscribe not yet confirmed
      this.onLossyNow = false;  // the message being handled came on the lossy channel
      const channels = lossyChannel ? [channel, lossyChannel] : [channel];
      let announced = false;
      const opened = () => {  // both settled: roslib may subscribe on either
        const lossySettled = !lossyChannel || lossyChannel.readyState !== "connecting";
        if (!announced && channel.readyState === "open" && lossySettled) {
          announced = true;  // a server that refuses the lossy channel closes it: go without
          this.emit("open", {});
        }
      };
      for (const c of channels) {
        c.binaryType = "arraybuffer";
        c.onopen = opened;
        c.onmessage = (e) => {
          this.onLossyNow = c === lossyChannel;
          this.handleRawMessage(e.data);
          this.onLossyNow = false;
        };
      }
      if (lossyChannel) lossyChannel.onclose = opened;
      channel.onclose = (e) => {
        this.forgetAll();
        this.emit("close", e);
      };
      channel.onerror = (e) => this.emit("error", e);
    }
    send(message) {
      const onLossy = message.op === "subscribe" && lossy.has(message.topic)
        && this.lossyChannel && this.lossyChannel.readyState === "open";
      if (message.op === "unsubscribe") this.forget(message.topic);
      const text = JSON.stringify(message);
      (onLossy ? this.lossyChannel : this.channel).send(text);
      if (onLossy) this.resend(message.topic, text, 0);
    }
    resend(topic, text, attempt) {  // until the topic's first lossy message (RESEND_MS)
      this.forget(topic);
      if (attempt >= RESEND_MS.length) return;
      this.unconfirmed.set(topic, setTimeout(() => {
        this.unconfirmed.delete(topic);
        if (this.lossyChannel.readyState !== "open") return;
        this.lossyChannel.send(text);
        this.resend(topic, text, attempt + 1);
      }, RESEND_MS[attempt]));
    }
    forget(topic) {
      clearTimeout(this.unconfirmed.get(topic));
      this.unconfirmed.delete(topic);
    }
    forgetAll() {
      for (const topic of [...this.unconfirmed.keys()]) this.forget(topic);
    }
    handleRosbridgeMessage(message) {  // decoded (JSON or CBOR), before fragments and png
      if (this.onLossyNow && this.unconfirmed.size && message.op === "publish") {
        this.forget(message.topic);  // the subscription reached the server
      }
      super.handleRosbridgeMessage(message);
    }
    close() {
      this.forgetAll();
      fetch(this.session, { method: "DELETE" }).catch(() => {});
      if (this.lossyChannel) this.lossyChannel.close();
      this.channel.close();
      this.pc.close();
    }
    isConnecting() { return this.channel.readyState === "connecting"; }
    isOpen() { return this.channel.readyState === "open"; }
    isClosing() { return this.channel.readyState === "closing"; }
    isClosed() { return this.channel.readyState === "closed"; }
  }

  // url: the server's http(s) URL ("http://robot.local:9090"), with or without /webrtc.
  return async function webrtcTransport(url) {
    const base = String(url).replace(/\/+$/, "").replace(/\/webrtc$/, "");
    const pc = new RTCPeerConnection(rtcConfiguration);
    const channel = pc.createDataChannel("rosbridge");
    const lossyChannel = lossy.size ? pc.createDataChannel("rosbridge-lossy", LOSSY) : null;
    await pc.setLocalDescription(await pc.createOffer());
    await new Promise((done) => {  // no trickle ICE: the offer goes with its candidates
      if (pc.iceGatheringState === "complete") return done();
      pc.addEventListener("icegatheringstatechange", () => {
        if (pc.iceGatheringState === "complete") done();
      });
    });
    const headers = { "Content-Type": "application/sdp" };
    if (token) headers.Authorization = `Bearer ${token}`;
    const reply = await fetch(`${base}/webrtc`, {
      method: "POST", headers, body: pc.localDescription.sdp,
    });
    if (reply.status !== 201) {
      pc.close();
      throw new Error(`WebRTC offer refused (${reply.status}): ${await reply.text()}`);
    }
    const session = new URL(reply.headers.get("Location"), base).href;
    await pc.setRemoteDescription({ type: "answer", sdp: await reply.text() });
    return new DataChannelTransport(pc, channel, lossyChannel, session);
  };
}
