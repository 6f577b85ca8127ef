"""A Foxglove client reduced to its session, for the sans-IO tests of tests/foxglove."""

from __future__ import annotations

import json
import struct

from rwt_foxglove import FoxgloveSession
from rwt_graph.graph import Graph
from rwt_protocol.runtime.rules import ClientRules


class Client:
    """Drives a session and keeps what it sent back, split into text ops and binary frames."""

    def __init__(
        self,
        graph: Graph,
        *,
        with_params: bool = False,
        client_id: str = "foxglove:test#1",
        run_jobs: bool = True,
        **kwargs: object,
    ) -> None:
        self.run_jobs = run_jobs
        if with_params:
            kwargs["params"] = graph.params
        if "access" in kwargs:  # the one per-client rule a test names most
            kwargs["config"] = ClientRules(access=kwargs.pop("access"))  # type: ignore[arg-type]
        self.session = FoxgloveSession(
            graph.port,
            client_id,
            session_id="s1",
            **kwargs,  # type: ignore[arg-type]
        )
        self.ops: list[dict[str, object]] = []
        self.binary: list[bytes] = []
        self.drain()

    now = 0.0
    """The time the client's frames arrive at (monotonic seconds, moved by hand)."""

    def drain(self) -> None:
        """Run what the transport would (background jobs, due timers) and take every frame."""
        session = self.session
        while True:
            while self.run_jobs and (job := session.jobs.take_background()) is not None:
                try:
                    result: object = job.run()
                except Exception as exc:
                    result = exc
                session.finish_job(job, result, self.now)
            session.handle_timer(self.now)
            frames = session.frames_to_send(1 << 20)
            if not frames:
                return
            for frame in frames:
                if frame.binary:
                    self.binary.append(frame.prefix + frame.data)
                else:
                    self.ops.append(json.loads(frame.data))

    def send(self, op: dict[str, object]) -> None:
        self.session.receive_frame(json.dumps(op).encode(), self.now, binary=False)
        self.drain()

    def send_raw(self, data: bytes, *, binary: bool) -> None:
        self.session.receive_frame(data, self.now, binary=binary)
        self.drain()

    def sync(self, now: float | None = None) -> None:
        if now is not None:
            self.now = now
        self.session.sync()
        self.drain()

    def take_ops(self, op: str) -> list[dict[str, object]]:
        found = [each for each in self.ops if each["op"] == op]
        self.ops = [each for each in self.ops if each["op"] != op]
        return found

    def channel(self, topic: str) -> dict[str, object]:
        for op in self.ops:
            if op["op"] == "advertise":
                for channel in op["channels"]:  # type: ignore[attr-defined]
                    if channel["topic"] == topic:
                        return channel  # type: ignore[no-any-return]
        raise AssertionError(f"{topic} not advertised: {self.ops}")

    def service(self, name: str) -> dict[str, object]:
        for op in self.ops:
            if op["op"] == "advertiseServices":
                for service in op["services"]:  # type: ignore[attr-defined]
                    if service["name"] == name:
                        return service  # type: ignore[no-any-return]
        raise AssertionError(f"{name} not advertised: {self.ops}")

    def data(self) -> list[tuple[int, int, bytes]]:
        out = []
        for frame in self.binary:
            assert frame[0] == 1
            sid, log_time = struct.unpack_from("<IQ", frame, 1)
            out.append((sid, log_time, frame[13:]))
        self.binary = []
        return out

    def call(self, service_id: int, call_id: int, payload: bytes, encoding: str = "cdr") -> None:
        name = encoding.encode()
        header = struct.pack("<BIII", 2, service_id, call_id, len(name))
        self.send_raw(header + name + payload, binary=True)

    def responses(self) -> list[tuple[int, int, str, bytes]]:
        """The service call responses received: (service id, call id, encoding, payload)."""
        out = []
        rest = []
        for frame in self.binary:
            if frame[0] != 3:
                rest.append(frame)
                continue
            service_id, call_id, length = struct.unpack_from("<III", frame, 1)
            encoding = frame[13 : 13 + length].decode()
            out.append((service_id, call_id, encoding, frame[13 + length :]))
        self.binary = rest
        return out


def cdr(graph: Graph, type_name: str, msg: dict[str, object]) -> bytes:
    """``msg`` of ``type_name`` (a message, or a service's ``..._Request``) as CDR."""
    mtype = graph.registry.message(type_name)
    return graph.registry.serialize(mtype, mtype.from_python(msg))
