"""Conformance tests run on asyncio (the runner's connectors are anyio, trio would work too)."""

from __future__ import annotations
