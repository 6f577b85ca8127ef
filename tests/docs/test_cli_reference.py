"""docs/cli.md is what the ``rwt`` command says of itself."""

from __future__ import annotations

from rwt_cli.reference import render

from .blocks import REPO


def test_the_cli_reference_is_up_to_date() -> None:
    committed = (REPO / "docs" / "cli.md").read_text("utf-8")
    assert committed == render(), "docs/cli.md is stale: python -m rwt_cli.reference > docs/cli.md"


def test_the_reference_lists_every_serve_option() -> None:
    page = render()
    for option in ("--port", "--tcp-port", "--max-message-size", "--video-port", "--uvloop"):
        assert f"`{option}`" in page
