"""Chromium's lossy subscriptions across a link that loses what the browser sends.

A ``subscribe`` sent on ``rosbridge-lossy`` is itself never retransmitted: one lost on
the way made a subscription that delivered nothing, for as long as the page ran (a
page's session A, with ``/fast`` and ``/chatter`` on the lossy channel, got every
``/chatter`` message and no ``/fast`` one: the server never had the subscription). rwt's
roslib transport sends such a subscribe again until its topic's first message comes on
the lossy channel (docs/webrtc.md, "The lossy channel"). Here Chromium (roslib and the
transport rwt serves) is behind benchmarks/wanlink.py's link, in its own network
namespace, and a fifth of the packets it sends are lost: each of ``TOPICS`` topics,
subscribed one by one on the lossy channel (so each subscribe goes in a packet of its
own), delivers. Skipped, with the reason, without root, TUN devices or Chromium.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from benchmarks.wanlink import LinkProfile, WanLink, in_netns

from tests.browser.cdp import Browser, chromium_path
from tests.support import netns
from tests.support.realclients import REPO
from tests.webrtc.pagesite import MODULES, serve_pages
from tests.webrtc.test_browser import IMPORTS

pytestmark = pytest.mark.anyio

ROBOT, BROWSER = "198.18.7.1", "198.18.7.2"
PORT = 9090
TOPICS = 12
UP_LOSS = 0.2
"""Packets lost from the browser to the robot (none the other way). Without the resends,
all twelve subscribes arrive at 0.8 ** 12, 7 % of runs."""
ENV = {**os.environ, "PYTHONPATH": f"{REPO / 'src'}:{REPO}", "PYTHONUNBUFFERED": "1"}

PAGE = """
import { Ros, Topic, AbstractTransport } from "roslib";
const sleep = (ms) => new Promise((ok) => setTimeout(ok, ms));
async function connect(options) {
  const ros = new Ros(options);
  await new Promise((ok, fail) => { ros.on("connection", ok); ros.on("error", fail); });
  return ros;
}
window.run = async (base, count) => {
  const { webrtcTransportFactory } = await import(base + "/webrtc/roslib-transport.js");
  const names = [...Array(count).keys()].map((i) => `/lossy_${i}`);
  const factory = (lossyTopics) => webrtcTransportFactory(AbstractTransport, { lossyTopics });
  const publisher = await connect({ url: base, transportFactory: factory([]) });
  const subscriber = await connect({ url: base, transportFactory: factory(names) });
  const got = Object.fromEntries(names.map((name) => [name, 0]));
  for (const name of names) {  // one subscribe a packet: each is lost or not on its own
    new Topic({ ros: subscriber, name, messageType: "std_msgs/String" })
      .subscribe(() => { got[name] += 1; });
    await sleep(40);
  }
  const topics = names.map(
    (name) => new Topic({ ros: publisher, name, messageType: "std_msgs/String" }));
  const deadline = Date.now() + 20000;  // a failure bound: resends take 12.8 s at most
  while (Object.values(got).some((n) => n === 0) && Date.now() < deadline) {
    for (const topic of topics) topic.publish({ data: "x" });
    await sleep(50);
  }
  subscriber.close();
  publisher.close();
  return got;
};
"""


def _page(path: str, _query: str) -> str | None:
    if path != "/":
        return None
    imports = {name: f"/node_modules/{file}" for name, file in IMPORTS.items()}
    return (
        "<!doctype html><html><head>"
        f'<script type="importmap">{json.dumps({"imports": imports})}</script>'
        f'<script type="module">{PAGE}</script></head><body>lossy</body></html>'
    )


@pytest.fixture
def hosts() -> Iterator[tuple[netns.Host, netns.Host]]:
    """The robot's and the browser's namespaces, joined by a link lossy from the browser."""
    reason = netns.unavailable(("tun",))
    if reason is not None:
        pytest.skip(reason)
    if chromium_path() is None:
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run does it as root)")
    if not (MODULES / "roslib").is_dir():
        pytest.skip("roslib is not installed: npm ci --prefix tests/js")
    with netns.namespaces("robot", "browser") as (robot, browser):
        up = LinkProfile(delay_s=0.005, jitter_s=0.0, loss=UP_LOSS, rate_bps=15e6)
        down = LinkProfile(delay_s=0.005, jitter_s=0.0, loss=0.0, rate_bps=15e6)
        link = WanLink(browser.ns, BROWSER, robot.ns, ROBOT, up, back=down)
        link.start()
        try:
            yield robot, browser
        finally:
            link.stop()


async def test_every_lossy_subscription_delivers_though_its_subscribe_may_be_lost(
    hosts: tuple[netns.Host, netns.Host], tmp_path: Path, stack: str
) -> None:
    robot, browser = hosts
    argv = [sys.executable, "-m", "rwt", "serve", "--log-level", "info", "--host", ROBOT]
    argv += ["--port", str(PORT), "--webrtc", "--webrtc-stack", stack]
    server = robot.start(argv, tmp_path / "robot.log", ENV)
    await server.wait_for("listening on ws://")
    executable = chromium_path()
    assert executable is not None
    with ExitStack() as stack_of:
        # made in the browser's namespace: Chromium, its DevTools socket and the page's site
        chromium = in_netns(browser.ns, lambda: Browser(executable, reachable=(ROBOT,)))
        stack_of.callback(chromium.close)
        site = in_netns(browser.ns, lambda: stack_of.enter_context(serve_pages(_page)))
        page = chromium.new_page()
        page.goto(site + "/")
        page.wait_for("typeof window.run === 'function'", 30, "the page's script")
        page.evaluate(
            f"run('http://{ROBOT}:{PORT}', {TOPICS}).then((got) => {{ window.got = got; }},"
            " (e) => { window.got = {failure: String(e)}; }); 0"
        )
        got = page.wait_for("window.got", 60, "every lossy topic, or the page's bound")
    log = (tmp_path / "robot.log").read_text("utf-8", "replace")
    assert got == {f"/lossy_{i}": got[f"/lossy_{i}"] for i in range(TOPICS)}, got
    assert all(count > 0 for count in got.values()), f"{got}\n{log[-3000:]}"
    assert "event=lossy_channel" in log  # they came on the lossy channel
