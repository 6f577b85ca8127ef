"""Setting ``RWT_NO_SHORTCUTS`` for one test (rwt_protocol.shortcuts)."""

from __future__ import annotations

import pytest

from rwt_protocol.shortcuts import ENV_VAR


def switch_off(monkeypatch: pytest.MonkeyPatch, names: str | None) -> None:
    """Switch the shortcuts ``names`` off (``RWT_NO_SHORTCUTS`` syntax); None: every one on.

    Read where each call site is built (``shortcuts.enabled``): set it before
    the objects under test are made.
    """
    if names is None:
        monkeypatch.delenv(ENV_VAR, raising=False)
    else:
        monkeypatch.setenv(ENV_VAR, names)
