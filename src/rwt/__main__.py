"""``python -m rwt``: the ``rwt`` command."""

from rwt._cli import main

main()
