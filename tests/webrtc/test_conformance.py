"""``rwt conformance webrtc+http://...`` against ``rwt serve --webrtc``: the suite over WebRTC."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import anyio.to_thread
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from rwt_conformance.runner import NEEDS_SECRET
from tests.support.cli import run_rwt, rwt_serve

pytestmark = pytest.mark.anyio

RUN_LIMIT_S = 300  # the whole suite on a loaded machine: only a hang reaches it
AUTH_REQUIREMENTS = {"D23", "spec1.auth.required"}  # they need a server with a secret


async def test_the_strict_profile_passes_over_the_data_channel(tmp_path: Path, stack: str) -> None:
    """On each stack (D51): on the native one, a hundred peer connections opened and closed
    in turn (it found a hang: answers waiting on libdatachannel's busy thread pool)."""
    report = tmp_path / "report.json"
    serve = ("--port", "0", "--webrtc", "--webrtc-stack", stack, "--log-level", "error")
    async with rwt_serve(*serve) as (_, urls):
        url = urls["ws"].strip().replace("ws://", "webrtc+http://") + "/webrtc"
        conformance = functools.partial(
            run_rwt, "conformance", url, "--json", str(report), timeout=RUN_LIMIT_S
        )
        run = await anyio.to_thread.run_sync(conformance)
    assert run.returncode == 0, run.stdout[-3000:]
    document = json.loads(report.read_text())
    assert document["summary"]["failed"] == 0
    skipped = {r["id"]: r["detail"] for r in document["requirements"] if r["result"] == "skipped"}
    assert document["spec_version"]["version"] == "2.1.0"  # GET /version, over HTTP as signalling
    by_version = skipped.pop("spec.publish.type-ignored")  # holds before 2.0.0 only
    assert "the server is judged by spec 2.1.0" in by_version
    assert skipped == dict.fromkeys(AUTH_REQUIREMENTS, NEEDS_SECRET)  # an open server
    assert document["summary"]["passed"] == len(document["requirements"]) - len(skipped) - 1 >= 190
    assert "D24" in run.stdout and "D30" in run.stdout  # the size cases ran over WebRTC too
