"""Fixtures of the safety envelope's tests: Chromium, shared with tests/browser."""

from tests.browser.conftest import browser  # noqa: F401 (Chromium, one a test process)
