"""The ``rwt`` command line: a module a command, over the server and its applications.

``rwt_cli.app.app`` is the typer application (the ``rwt`` console script and
``python -m rwt`` run it). A module a command: ``serve``, ``play``, ``record``,
``bag`` (``rwt bag ...``) and ``router`` (``rwt conformance`` is
``rwt_conformance.cli``); ``serve_options`` holds the option groups of ``rwt
serve``, ``bag_options`` the recording and playback options several commands
share, ``reference`` the generator of docs/cli.md. Nothing else in rwt imports
this package.
"""
