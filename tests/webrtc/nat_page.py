"""The page Chromium runs in tests/webrtc/test_nat.py, and the server that serves it.

``python -m tests.webrtc.nat_page PORT RESULT`` serves, on 127.0.0.1:PORT of
the browser's namespace, a page that does in Chromium what nat_peer.py does in
aiortc: offer a ``rosbridge`` data channel to the robot (``?server=``, passing
``?stun=`` as ``iceServers``, as docs/webrtc.md's "The page" says), do a
rosbridge round trip on it, and post what it saw to ``/result``, which is
written to the file RESULT: the candidate types and mDNS host names of its
offer, the remote address of the ICE pair in use, the echo.
"""

from __future__ import annotations

import http.server
import sys
from pathlib import Path

PAGE = """<!doctype html><html><body><script type="module">
const query = new URL(location.href).searchParams;
const report = (result) => fetch("/result", { method: "POST", body: JSON.stringify(result) });
try {
  const stun = query.get("stun");  // none: Chromium's host (mDNS) candidates only
  const pc = new RTCPeerConnection({ iceServers: stun ? [{ urls: stun }] : [] });
  const channel = pc.createDataChannel("rosbridge");
  await pc.setLocalDescription(await pc.createOffer());
  await new Promise((done) => {
    if (pc.iceGatheringState === "complete") return done();
    pc.onicegatheringstatechange = () => pc.iceGatheringState === "complete" && done();
  });
  const offer = pc.localDescription.sdp;
  const reply = await fetch(`${query.get("server")}/webrtc`, {
    method: "POST", headers: { "Content-Type": "application/sdp" }, body: offer,
  });
  if (reply.status !== 201) throw new Error(`offer refused: ${await reply.text()}`);
  await pc.setRemoteDescription({ type: "answer", sdp: await reply.text() });
  await new Promise((open) => { channel.onopen = open; });
  const echo = new Promise((got) => {
    channel.onmessage = (e) => {
      const message = JSON.parse(e.data);
      if (message.op === "publish") got(message.msg);
      if (message.op === "service_response") {
        channel.send(JSON.stringify({ op: "publish", topic: "/nat_echo",
                                      msg: { data: "through the NAT" } }));
      }
    };
  });
  for (const op of [
    { op: "advertise", topic: "/nat_echo", type: "std_msgs/String" },
    { op: "subscribe", topic: "/nat_echo", type: "std_msgs/String" },
    { op: "call_service", service: "/rosapi/topics", id: "sync" },
  ]) channel.send(JSON.stringify(op));
  const msg = await echo;
  // the pair in use: the transport's selected one (or the nominated one), which the
  // stats may list a moment after the channel opened
  let stats = [], pair;
  for (let tries = 0; !pair && tries < 50; tries++) {
    if (tries) await new Promise((later) => setTimeout(later, 100));
    stats = [...(await pc.getStats()).values()];
    const transport = stats.find((s) => s.type === "transport");
    pair = stats.find((s) => transport && s.id === transport.selectedCandidatePairId) ||
      stats.find((s) => s.type === "candidate-pair" && s.nominated && s.state === "succeeded");
  }
  if (!pair) throw new Error("no candidate pair in use in the stats");
  const remote = stats.find((s) => s.id === pair.remoteCandidateId);
  const lines = offer.split("\\r\\n").filter((l) => l.includes(" typ "));
  await report({
    echo: msg,
    offer_types: [...new Set(lines.map((l) => l.split(" typ ")[1].split(" ")[0]))].sort(),
    offer_mdns: lines.some((l) => l.split(" ")[4].endsWith(".local")),
    remote: [remote.address, remote.port],
  });
} catch (e) { await report({ failure: String(e) }); }
</script></body></html>"""


class _Page(http.server.BaseHTTPRequestHandler):
    result: Path

    def do_GET(self) -> None:
        body = PAGE.encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def do_POST(self) -> None:
        length = int(self.headers.get("Content-Length", "0"))
        self.result.write_bytes(self.rfile.read(length))
        self.send_response(204)
        self.end_headers()

    def log_message(self, format: str, *args: object) -> None:
        pass


if __name__ == "__main__":
    _Page.result = Path(sys.argv[2])
    server = http.server.HTTPServer(("127.0.0.1", int(sys.argv[1])), _Page)
    print("page up", flush=True)
    server.serve_forever()
