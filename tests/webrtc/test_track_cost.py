"""benchmarks/webrtc_track_cost.py at its smallest: a video track's cost per viewer on both
stacks (aiortc against libdatachannel's packetizer), bare and through rwt's server, every
viewer getting frames."""

from __future__ import annotations

import pytest

from rwt_transports.webrtc.native import native_missing
from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)


@pytest.mark.parametrize("through", ["bare", "rwt"])
def test_the_track_cost_benchmark_runs_on_aiortc_and_native(
    capsys: pytest.CaptureFixture[str], through: str
) -> None:
    if (missing := native_missing()) is not None:
        pytest.skip(missing)
    from benchmarks.webrtc_track_cost import main  # noqa: PLC0415 (after the skips)

    assert main(["--smoke", "--viewers", "2", "--through", through]) == 0
    rows = [line.strip("|").split("|") for line in capsys.readouterr().out.splitlines()[2:]]
    assert sorted(row[1].strip() for row in rows) == ["aiortc", "native"]
    for row in rows:
        assert row[0].strip() == "2"
        assert float(row[5]) > 0  # each viewer decoded frames
