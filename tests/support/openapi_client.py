"""An environment of its own for openapi-python-client, the code generator of tests/http.

tests/http/test_codegen.py generates a client from the HTTP API's OpenAPI document
and drives the robot with it. The generator is a tool, not a dependency of the suite:
its pins (typer below 0.28) are older than rwt's, so it runs from an environment of its
own, as a user installs it (``pipx install openapi-python-client``).
``RWT_OPENAPI_PYTHON_CLIENT`` names its command; else one on PATH; else one is made
once under ``~/.cache/rwt-tests`` with pip (about 15 s) and reused after. The xdist
controller starts it before its workers (``helper_envs``).
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
from pathlib import Path

from . import toolenv

__all__ = ["GENERATOR_PIN", "openapi_generator"]

GENERATOR_PIN = "openapi-python-client==0.29.1"
"""The release tests/http/test_codegen.py generates its client with."""
_HOME = toolenv.HOME / GENERATOR_PIN.replace("==", "-")
_BIN = toolenv.bin_dir(_HOME)


def _command() -> Path:
    return _BIN / (
        "openapi-python-client.exe" if sys.platform == "win32" else "openapi-python-client"
    )


@functools.cache
def openapi_generator() -> tuple[Path | None, str]:
    """The generator's command: ``(path, "")``, or ``(None, why not)``."""
    named = os.environ.get("RWT_OPENAPI_PYTHON_CLIENT") or shutil.which("openapi-python-client")
    if named:
        return Path(named), ""
    command = _command()
    if toolenv.is_ready(_HOME):  # made (by an earlier run or another process) and checked
        return command, ""
    with toolenv.locked(_HOME):
        if toolenv.is_ready(_HOME):
            return command, ""
        python, why = toolenv.make(_HOME, GENERATOR_PIN)
        if python is None:
            return None, why
        probe = subprocess.run(
            [str(command), "--version"], capture_output=True, text=True, check=False, timeout=120
        )
        if probe.returncode != 0:
            shutil.rmtree(_HOME, ignore_errors=True)
            return None, f"{GENERATOR_PIN} was installed in {_HOME} but does not run"
        toolenv.mark_ready(_HOME)
    return command, ""
