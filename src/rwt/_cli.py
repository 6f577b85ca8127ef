"""The ``rwt`` command's entry point: the CLI, or a clear word when its extra is missing."""

from __future__ import annotations

import sys

from rwt_protocol.distribution import install_hint


def main() -> None:
    """Run the ``rwt`` command (``rwt_cli``).

    The CLI needs the server extra (typer, rich, the graph's rosbags and numpy);
    an install of the client alone gets one line saying how to add it, not a
    traceback.
    """
    try:
        from rwt_cli.app import app  # noqa: PLC0415 - only the command loads the CLI
    except ModuleNotFoundError as exc:
        sys.stderr.write(
            f"rwt: the command line needs the server extra ({exc.name} is missing): "
            f"python -m {install_hint('server')}\n"
        )
        raise SystemExit(2) from None
    app()
