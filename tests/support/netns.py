"""A small internet in network namespaces: a robot and a browser each behind NAT, a TURN server.

``nat_topology()`` builds six namespaces joined by veth pairs, all addressed in
198.18.0.0/15 (RFC 2544's benchmarking range: no real host is there, and none of
these namespaces has a link to the machine's own interfaces)::

    robot 198.18.1.2 -- .1.1 nat .0.2 ------ .0.1 internet .3.1 -- .3.2 turn
    browser 198.18.2.2 -- .2.1 browser-nat .4.2 -- .4.1 internet

- ``nat`` and ``browser-nat`` are home routers: they masquerade (iptables
  ``MASQUERADE``, Linux's port-preserving NAT with address-and-port-dependent
  filtering: an outside host gets in only where the inside one sent first). The
  robot's also forwards one TCP port, the signalling port, to the robot
  (``SIGNALLING_PORT``), as a router's port forward or a reverse proxy does; UDP
  from outside is not forwarded. Neither side's host address is reachable from
  the other: without STUN or TURN no ICE pair can work.
- ``internet`` routes between the NATs' public sides and the TURN server;
  ``Topology.only_turn_reachable()`` drops UDP between the two NATs there, so the
  peers' media can only go through TURN.

It needs root (``ip netns add``, veth, iptables); ``unavailable()`` says why it
cannot be built here, for the test to skip with. Each process started in a
namespace is ended with it (``Topology.close``).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path

import anyio

SIGNALLING_PORT = 9090
"""The robot's WebSocket and signalling port, forwarded by the NAT (each namespace has
its own ports, so no test's port can collide with this one)."""

ROBOT = "198.18.1.2"
NAT_INSIDE = "198.18.1.1"
NAT_PUBLIC = "198.18.0.2"
INTERNET = "198.18.0.1"
BROWSER = "198.18.2.2"
BROWSER_NAT_PUBLIC = "198.18.4.2"
TURN = "198.18.3.2"

TURN_USER = "robot"
TURN_PASSWORD = "s3cret:with@signs"
"""The TURN server's one user (long-term credentials); its password has the characters
an ``--ice-server`` URL must percent-encode."""

_STEP_TIMEOUT_S = 20.0
"""Bounds a hung command or a server that never starts: a failure, not a measurement."""


_PACKAGES = {"ip": "iproute2", "iptables": "iptables", "turnserver": "coturn"}


def unavailable(tools: tuple[str, ...] = ("iptables", "turnserver")) -> str | None:
    """Why namespaces with ``tools`` cannot be had here (a skip reason), or None.

    Args:
        tools: the commands the test runs in them besides ``ip`` (``iptables``,
            ``turnserver``; ``tun`` for /dev/net/tun).
    """
    for tool in ("ip", *tools):
        if tool == "tun":
            if not os.path.exists("/dev/net/tun"):
                return "no /dev/net/tun: the WAN link needs TUN devices"
        elif shutil.which(tool) is None:
            package = _PACKAGES.get(tool, tool)
            return f"{tool} is not installed (apt-get install {package}; .ci/run does it as root)"
    if os.geteuid() != 0:
        return "network namespaces with veth and iptables need root (ip netns add)"
    probe = f"rwtprobe{os.getpid()}"
    made = _ip("netns", "add", probe)
    if made.returncode != 0:
        return f"ip netns add fails here: {made.stderr.strip()}"
    try:
        if "iptables" in tools:
            nat = _ip_netns(probe, "iptables", "-t", "nat", "-L", "-n", check=False)
            if nat.returncode != 0:
                return f"iptables' nat table does not work in a namespace: {nat.stderr.strip()}"
    finally:
        _ip("netns", "del", probe)
    return None


@contextmanager
def namespaces(*roles: str) -> Iterator[list[Host]]:
    """Bare namespaces (only ``lo``, up), one a role; deleted, their processes ended, on exit."""
    hosts = [Host(f"rwt{os.getpid()}-{role}", "") for role in roles]
    try:
        for item in hosts:
            made = _ip("netns", "add", item.ns)
            if made.returncode != 0:
                raise RuntimeError(f"ip netns add {item.ns}: {made.stderr.strip()}")
            item.run("ip", "link", "set", "lo", "up")
        yield hosts
    finally:
        _close(hosts)


def _ip(*argv: str) -> subprocess.CompletedProcess[str]:
    """``ip ARGV`` in this namespace; its result, whether it worked or not."""
    return subprocess.run(
        ["ip", *argv], check=False, capture_output=True, text=True, timeout=_STEP_TIMEOUT_S
    )


def _ip_netns(ns: str, *argv: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    done = _ip("netns", "exec", ns, *argv)
    if check and done.returncode != 0:
        raise RuntimeError(f"in {ns}: {' '.join(argv)}: {done.stderr.strip()}")
    return done


@dataclass
class Host:
    """One namespace and its address on the topology."""

    ns: str
    address: str
    started: list[subprocess.Popen[bytes]] = field(default_factory=list)

    def run(self, *argv: str) -> str:
        """Run a command in this namespace to its end; its stdout.

        Raises:
            RuntimeError: it failed (its stderr).
        """
        return _ip_netns(self.ns, *argv).stdout

    def start(self, argv: Sequence[str], log: Path, env: dict[str, str] | None = None) -> Started:
        """Start ``argv`` in this namespace, its stdout and stderr to ``log``.

        It is killed with the topology (``Topology.close``), or earlier by ``stop``.
        """
        with log.open("wb") as out:
            process = subprocess.Popen(
                ["ip", "netns", "exec", self.ns, *argv],
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
            )
        self.started.append(process)
        return Started(process, log)


@dataclass
class Started:
    """A process started in a namespace, and the file its output goes to."""

    process: subprocess.Popen[bytes]
    log: Path

    async def wait_for(self, text: str) -> str:
        """Wait until its output holds ``text``; the output so far.

        Raises:
            RuntimeError: it exited first, or did not print it in 20 s (with its output).
        """
        with anyio.move_on_after(_STEP_TIMEOUT_S):
            while True:
                output = self.log.read_text("utf-8", "replace")
                if text in output:
                    return output
                if self.process.poll() is not None:
                    break
                await anyio.sleep(0.05)
        output = self.log.read_text("utf-8", "replace")
        raise RuntimeError(f"no {text!r} (exit {self.process.poll()}):\n{output[-3000:]}")

    def stop(self) -> None:
        """End it (SIGTERM, then SIGKILL after 5 s)."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


@dataclass
class Topology:
    """The six namespaces; ``close()`` ends their processes and deletes them."""

    prefix: str
    robot: Host = field(init=False)
    nat: Host = field(init=False)
    internet: Host = field(init=False)
    browser: Host = field(init=False)
    browser_nat: Host = field(init=False)
    turn: Host = field(init=False)

    def __post_init__(self) -> None:
        def host(role: str, address: str) -> Host:
            return Host(f"{self.prefix}-{role}", address)

        self.robot = host("robot", ROBOT)
        self.nat = host("nat", NAT_PUBLIC)
        self.internet = host("internet", INTERNET)
        self.browser = host("browser", BROWSER)
        self.browser_nat = host("bnat", BROWSER_NAT_PUBLIC)
        self.turn = host("turn", TURN)

    @property
    def hosts(self) -> tuple[Host, ...]:
        return (self.robot, self.nat, self.internet, self.browser, self.browser_nat, self.turn)

    def build(self) -> None:
        """Make the namespaces, their links, routes and the NAT's rules."""
        for item in self.hosts:
            made = _ip("netns", "add", item.ns)
            if made.returncode != 0:
                raise RuntimeError(f"ip netns add {item.ns}: {made.stderr.strip()}")
            item.run("ip", "link", "set", "lo", "up")
        self._link(self.robot, "eth0", ROBOT, self.nat, "lan", NAT_INSIDE)
        self._link(self.nat, "wan", NAT_PUBLIC, self.internet, "tonat", INTERNET)
        self._link(self.browser, "eth0", BROWSER, self.browser_nat, "lan", "198.18.2.1")
        self._link(
            self.browser_nat, "wan", BROWSER_NAT_PUBLIC, self.internet, "tobnat", "198.18.4.1"
        )
        self._link(self.turn, "eth0", TURN, self.internet, "toturn", "198.18.3.1")
        for item, gateway in (
            (self.robot, NAT_INSIDE),
            (self.nat, INTERNET),
            (self.browser, "198.18.2.1"),
            (self.browser_nat, "198.18.4.1"),
            (self.turn, "198.18.3.1"),
        ):
            item.run("ip", "route", "add", "default", "via", gateway)
        for router in (self.nat, self.browser_nat, self.internet):
            router.run("sysctl", "-qw", "net.ipv4.ip_forward=1")
        for router in (self.nat, self.browser_nat):
            self._masquerade(router)
        forward = f"{ROBOT}:{SIGNALLING_PORT}"
        self.nat.run(
            "iptables", "-t", "nat", "-I", "PREROUTING", "-i", "wan", "-p", "tcp",
            "--dport", str(SIGNALLING_PORT), "-j", "DNAT", "--to-destination", forward,
        )  # fmt: skip

    @staticmethod
    def _masquerade(router: Host) -> None:
        """A home router's rules: out through ``wan`` masqueraded; in, only replies.

        Linux's MASQUERADE keeps the source port where it can, so the mapping is the
        same whatever the destination, as most home routers' is (RFC 4787
        endpoint-independent mapping): hole punching through it works.
        """
        for rule in (
            ["-t", "nat", "-A", "POSTROUTING", "-o", "wan", "-j", "MASQUERADE"],
            [
                "-A",
                "FORWARD",
                "-i",
                "wan",
                "-m",
                "conntrack",
                "--ctstate",
                "ESTABLISHED,RELATED,DNAT",
                "-j",
                "ACCEPT",
            ],
            ["-A", "FORWARD", "-i", "wan", "-j", "DROP"],
            # Unasked-for packets to the router itself are dropped too, before conntrack
            # keeps them: a kept one would hold the port the inside host's next packet
            # out needs, and MASQUERADE would give that packet another (no hole punching).
            ["-A", "INPUT", "-i", "wan", "-m", "conntrack", "--ctstate", "NEW", "-j", "DROP"],
        ):
            router.run("iptables", *rule)

    @staticmethod
    def _link(a: Host, a_name: str, a_ip: str, b: Host, b_name: str, b_ip: str) -> None:
        """A veth pair from ``a`` to ``b``, both ends addressed in one /24 and up."""
        made = _ip("-n", a.ns, "link", "add", a_name, "type", "veth", "peer", "name", b_name,
                   "netns", b.ns)  # fmt: skip
        if made.returncode != 0:
            raise RuntimeError(f"veth {a.ns} - {b.ns}: {made.stderr.strip()}")
        for item, name, ip in ((a, a_name, a_ip), (b, b_name, b_ip)):
            item.run("ip", "addr", "add", f"{ip}/24", "dev", name)
            item.run("ip", "link", "set", name, "up")

    def only_turn_reachable(self) -> None:
        """Drop UDP between the two NATs: only TURN can carry the peers' media."""
        for source, target in ((NAT_PUBLIC, BROWSER_NAT_PUBLIC), (BROWSER_NAT_PUBLIC, NAT_PUBLIC)):
            self.internet.run(
                "iptables", "-A", "FORWARD", "-s", source, "-d", target, "-p", "udp", "-j", "DROP"
            )

    def turn_only_over_tcp(self) -> None:
        """Drop UDP from the robot's NAT to the TURN server's port: the robot reaches it
        over TCP only (``turn:...?transport=tcp``), as behind a firewall that lets out
        TCP alone; the relayed data still leaves coturn over UDP.
        """
        self.internet.run(
            "iptables", "-A", "FORWARD", "-s", NAT_PUBLIC, "-d", TURN,
            "-p", "udp", "--dport", "3478", "-j", "DROP",
        )  # fmt: skip

    def close(self) -> None:
        """End every process in the namespaces (only this topology's), then delete them."""
        _close(self.hosts)


def _close(hosts: Sequence[Host]) -> None:
    """End every process in these namespaces (they were made for a test), then delete them."""
    for item in hosts:
        for pid in _ip("netns", "pids", item.ns).stdout.split():
            with suppress(ProcessLookupError, ValueError):
                os.kill(int(pid), signal.SIGKILL)
        for process in item.started:  # reaped: `ip netns exec` ends with its child
            with suppress(subprocess.TimeoutExpired):
                process.wait(5)
        _ip("netns", "del", item.ns)


@contextmanager
def nat_topology() -> Iterator[Topology]:
    """The topology, built; deleted on exit (the caller skips first on ``unavailable()``)."""
    topology = Topology(f"rwt{os.getpid()}")
    try:
        topology.build()
        yield topology
    finally:
        topology.close()


COTURN_READY = "Total General servers"
"""What coturn prints once it listens."""


LAN_ROBOT = "198.18.6.2"
LAN_BROWSER = "198.18.6.3"


@contextmanager
def lan() -> Iterator[tuple[Host, Host]]:
    """The robot and the browser on one LAN segment (a veth pair: multicast reaches across).

    No NAT, no router: each has a route for everything (multicast DNS included) out
    of its one interface, as a host on a LAN does.
    """
    with namespaces("lan-robot", "lan-browser") as (robot, browser):
        robot.address, browser.address = LAN_ROBOT, LAN_BROWSER
        Topology._link(robot, "eth0", LAN_ROBOT, browser, "eth0", LAN_BROWSER)
        for item in (robot, browser):
            item.run("ip", "route", "add", "default", "dev", "eth0")
        yield robot, browser


def coturn_argv(host: Host, folder: Path) -> list[str]:
    """Debian's coturn as STUN and TURN server on ``host``: UDP 3478, one user, no TLS.

    Its configuration is written to ``folder`` (Debian's /etc/turnserver.conf, read
    without ``-c``, would log to syslog); it logs to stdout.
    """
    conf = folder / "turnserver.conf"
    conf.write_text(
        f"""listening-ip={host.address}
relay-ip={host.address}
listening-port=3478
min-port=49152
max-port=49999
lt-cred-mech
user={TURN_USER}:{TURN_PASSWORD}
realm=rwt.test
fingerprint
no-tls
no-dtls
no-cli
no-tcp-relay
log-file=stdout
simple-log
pidfile={folder / "turnserver.pid"}
userdb={folder / "turnserver.db"}
"""
    )
    return ["stdbuf", "-oL", "turnserver", "-c", str(conf)]
