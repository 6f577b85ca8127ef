"""``python -m rwt_cli``: the ``rwt`` command (as ``python -m rwt``)."""

from rwt_cli.app import app

app(prog_name="rwt")
