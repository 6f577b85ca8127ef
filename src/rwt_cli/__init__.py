"""The ``rwt`` command line: a module a command, over the server and its applications.

``rwt_cli.app.app`` is the typer application (the ``rwt`` console script and
``python -m rwt`` run it); ``serve``, ``play``, ``router`` and ``bag`` (``rwt
record``, ``rwt bag ...``) hold the commands, ``serve_options`` the option groups
of ``rwt serve``, ``reference`` the generator of docs/cli.md. Nothing else in rwt
imports this package.
"""
