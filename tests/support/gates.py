"""An inflow gate for link tests: every delivery congested a subscriber (``rwt_graph.link``)."""

from __future__ import annotations

import anyio

__all__ = ["CongestedGate"]


class _Hold:
    def __init__(self, drain_s: float) -> None:
        self._drain_s = drain_s

    async def wait(self) -> None:
        await anyio.sleep(self._drain_s)


class CongestedGate:
    """An ``InflowGate`` whose every delivery congested a subscriber draining in ``drain_s``."""

    def __init__(self, drain_s: float = 0.3) -> None:
        self._drain_s = drain_s

    def begin(self) -> None:
        pass

    def end(self) -> None:
        pass

    def congested(self) -> bool:
        return True

    def take_hold(self, publisher: str | None = None) -> _Hold:
        return _Hold(self._drain_s)
