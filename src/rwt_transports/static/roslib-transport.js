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
// (latest-only, never retransmitted: D36); token, a video token sent as
// `Authorization: Bearer` with the offer; rtcConfiguration, for RTCPeerConnection.

const LOSSY = { ordered: false, maxRetransmits: 0 };

export function webrtcTransportFactory(AbstractTransport, options = {}) {
  const { lossyTopics = [], token = null, rtcConfiguration = {} } = options;
  const lossy = new Set(lossyTopics);

  class DataChannelTransport extends AbstractTransport {
    constructor(pc, channel, lossyChannel, session) {
      super();
      Object.assign(this, { pc, channel, lossyChannel, session });
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
        c.onmessage = (e) => this.handleRawMessage(e.data);
      }
      if (lossyChannel) lossyChannel.onclose = opened;
      channel.onclose = (e) => this.emit("close", e);
      channel.onerror = (e) => this.emit("error", e);
    }
    send(message) {
      const onLossy = message.op === "subscribe" && lossy.has(message.topic)
        && this.lossyChannel && this.lossyChannel.readyState === "open";
      (onLossy ? this.lossyChannel : this.channel).send(JSON.stringify(message));
    }
    close() {
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
