// The console's way over WebRTC (docs/console.md, ?webrtc=1): the `rosbridge` data
// channel of `rwt serve --webrtc` behind the part of the WebSocket interface that
// rosbridge.js uses (readyState, onopen, onmessage, onclose, onerror, send, close).
// The offer, its candidates gathered, is posted to /webrtc on the page's own origin.

const STATES = { connecting: 0, open: 1, closing: 2, closed: 3 };

export class DataChannelSocket {
  constructor(base) {
    this.readyState = STATES.connecting;
    this.onopen = this.onmessage = this.onclose = this.onerror = null;
    this.session = null;
    this.pc = new RTCPeerConnection();
    this.channel = this.pc.createDataChannel('rosbridge');
    this.channel.onopen = () => {
      this.readyState = STATES.open;
      if (this.onopen) this.onopen({});
    };
    this.channel.onmessage = (event) => this.onmessage && this.onmessage({ data: event.data });
    this.channel.onclose = () => this.closed(1000, '');
    this.start(base).catch((error) => {
      if (this.onerror) this.onerror(error);
      this.closed(1006, String(error.message ?? error));
    });
  }

  async start(base) {
    const pc = this.pc;
    await pc.setLocalDescription(await pc.createOffer());
    await new Promise((done) => {
      if (pc.iceGatheringState === 'complete') return done();
      pc.addEventListener('icegatheringstatechange', () => pc.iceGatheringState === 'complete' && done());
    });
    const reply = await fetch(`${base}/webrtc`, {
      method: 'POST', headers: { 'Content-Type': 'application/sdp' }, body: pc.localDescription.sdp,
    });
    if (reply.status !== 201) throw new Error(`offer refused: ${reply.status} ${await reply.text()}`);
    this.session = new URL(reply.headers.get('Location'), base).href;
    await pc.setRemoteDescription({ type: 'answer', sdp: await reply.text() });
  }

  send(text) {
    this.channel.send(text);
  }

  close() {
    if (this.session) fetch(this.session, { method: 'DELETE' }).catch(() => {});
    this.closed(1000, '');
  }

  closed(code, reason) {
    if (this.readyState === STATES.closed) return;
    this.readyState = STATES.closed;
    this.channel.close();
    this.pc.close();
    if (this.onclose) this.onclose({ code, reason });
  }
}
