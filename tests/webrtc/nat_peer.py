"""The browser's side of tests/webrtc/test_nat.py, run in the browser's network namespace.

``python -m tests.webrtc.nat_peer BASE [--ice-server URL] [--wait S]`` offers to
``BASE``/webrtc with aiortc (peer.py's client, with the STUN server a browser page
would pass as ``iceServers``), does a rosbridge round trip on the data channel (advertise,
subscribe and publish ``/nat_echo``, receive the message back through the
server), and prints one JSON line: the candidate types of the answer, the
address the data channel's ICE pair reached the server at, and the echo.
"""

from __future__ import annotations

import argparse
import json

import anyio
from aiortc import RTCIceServer

from tests.webrtc import peer
from tests.webrtc.peer import rtc_client

TOPIC = "/nat_echo"


def _nominated_remote(client: object) -> list[object]:
    """The server's address of the ICE pair the data channel runs on: ``[host, port]``."""
    ice = client.pc.sctp.transport.transport  # type: ignore[attr-defined]
    pair = ice._connection._nominated[1]  # aioice's selected pair (no public accessor)
    return list(pair.remote_addr)


async def main(base: str, ice_servers: list[str]) -> None:
    servers = [RTCIceServer(urls=url) for url in ice_servers]
    async with rtc_client(base, ice_servers=servers) as client:
        answer = client.pc.remoteDescription.sdp
        types = sorted(
            {
                line.split(" typ ", 1)[1].split()[0]
                for line in answer.splitlines()
                if " typ " in line
            }
        )
        client.send({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"})
        client.send({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String"})
        client.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
        await client.next_op("service_response")  # the subscription is in place
        client.send({"op": "publish", "topic": TOPIC, "msg": {"data": "through the NAT"}})
        echo = await client.next_op("publish")
        result = {"candidates": types, "remote": _nominated_remote(client), "echo": echo["msg"]}
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("base")
    parser.add_argument("--ice-server", action="append", default=[])
    parser.add_argument("--wait", type=float, default=peer.RECEIVE_S)
    args = parser.parse_args()
    peer.RECEIVE_S = args.wait  # the control test's peer gives up sooner
    anyio.run(main, args.base, args.ice_server)
