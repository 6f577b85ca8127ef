"""roslib (roslibjs) in Node: a subscriber on one connection gets what another publishes.

Each round opens two new connections, subscribes with a throttle and a queue on
one and publishes right after on the other (tests/js/arrival.mjs): the pattern
of roslibjs test suites, which failed now and then when the server handled the
publisher's first frames before the subscriber's (docs/limits.md, arrival order).
"""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from tests.integration.client_harness import JS_DIR, ServerProcess

pytestmark = pytest.mark.node

ROUNDS = 100


def test_roslib_subscribers_get_what_another_connection_publishes(
    rwt_server: ServerProcess,
) -> None:
    node = shutil.which("node")
    assert node is not None
    done = subprocess.run(
        [node, str(JS_DIR / "arrival.mjs"), rwt_server.url, str(ROUNDS)],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result == {"rounds": ROUNDS, "missed": []}
