"""The record-and-replay tests run their async parts on asyncio (the server's loop)."""

from __future__ import annotations
