"""``python -m rwt_transports`` runs the ``rwt`` command line."""

from rwt_transports.cli import app

app(prog_name="rwt")
