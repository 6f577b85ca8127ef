"""Build tf2_msgs for rclpy from the message text rwt carries: PyPI has no Kilted wheel of it.

Usage: python -m tests.ros2.tf2_msgs_build [--force]     (prints the install prefix)

rclpy can carry a type only with its generated package (C type support and the Python
classes), and PyPI's ROS 2 Kilted wheels have none for tf2_msgs. They do have the
rosidl generators and ament_cmake, so this builds one from
``src/rwt_graph/interfaces/tf2_msgs/msg`` (``TFMessage``) with the CMake package in
``data/tf2_msgs_package``:

1. a venv of this Python with the generators, pinned to the ROS 2 wheels installed
   here (same versions, so the built libraries fit the runtime rclpy loads);
2. the wheels' exported CMake targets name the wheel builder's Python and numpy include
   folders (``/opt/python/cp311-cp311/...``): pointed at this venv's, in the venv;
3. ``cmake`` configure, build (2 jobs), install into the prefix.

It needs a C and C++ compiler and make (``apt-get install build-essential``), the
Python headers, cmake 3.20+ (PyPI's ``cmake`` wheel is taken when there is none) and
PyPI. The prefix is cached by a key of everything the build reads (``RWT_TF2_MSGS_DIR``
or ``~/.cache/rwt``); a second call finds it. On this project's 2-core machine the
whole build took 30-40 s (about half of it pip, the same with an empty pip cache), and
the prefix is under 1 MB. ``runtime_env`` says what a process needs to import
``tf2_msgs``.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import hashlib
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterator

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
MESSAGES = REPO / "src" / "rwt_graph" / "interfaces" / "tf2_msgs" / "msg"
PACKAGE = HERE / "data" / "tf2_msgs_package"
COMMAND = "python -m tests.ros2.tf2_msgs_build"

#: What the build venv holds beyond the message packages tf2_msgs depends on.
BUILD_WHEELS = [
    "ros-kilted-geometry-msgs",
    "ros-kilted-rosidl-default-generators",
    "ros-kilted-rosidl-default-runtime",
    "ros-kilted-rosidl-generator-py",
    "ros-kilted-rosidl-adapter",
    "ros-kilted-rosidl-core-generators",
    "ros-kilted-ament-cmake",
    "ros-kilted-ament-cmake-ros-core",
    "ros-kilted-ament-cmake-python",
    "ros-kilted-ament-cmake-include-directories",
    "ros-kilted-ament-package",
    "catkin_pkg",  # ament_cmake reads package.xml with it
    "numpy",  # rosidl_generator_py's C code includes its headers
]
#: The tools the build runs that no wheel brings.
TOOLS = ("cc", "c++", "make")
DONE = ".rwt-built"
BUILDER_PYTHON = re.compile(r"/opt/python/cp3\d+-cp3\d+/")


class BuildError(RuntimeError):
    """The build failed; the text ends with the log's last lines."""


def missing_tools() -> list[str]:
    """What the build needs that is not here (empty when it can run)."""
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    include = Path(sysconfig.get_paths()["include"])
    if not (include / "Python.h").is_file():
        missing.append(f"Python.h in {include} (the python3 dev headers)")
    return missing


def _pins() -> list[str]:
    """``name==version`` of the ROS 2 wheels and numpy installed for this Python."""
    pins = {}
    for dist in importlib.metadata.distributions():
        name = (dist.metadata["Name"] or "").lower()
        if name.startswith("ros-") or name == "numpy":
            pins[name] = f"{name}=={dist.version}"
    return sorted(pins.values())


def prefix() -> Path:
    """Where the build for this Python, these wheels and this text is (built or not)."""
    digest = hashlib.sha256()
    for path in sorted([*MESSAGES.glob("*.msg"), *PACKAGE.iterdir()]):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update("\n".join([sys.version, *BUILD_WHEELS, *_pins()]).encode())
    root = os.environ.get("RWT_TF2_MSGS_DIR") or Path.home() / ".cache" / "rwt"
    return Path(root) / f"tf2_msgs-{digest.hexdigest()[:16]}"


def is_built(where: Path) -> bool:
    """Whether ``where`` (a ``prefix()``) holds a finished build."""
    return (where / "install" / DONE).is_file()


def runtime_env(where: Path) -> dict[str, str]:
    """``PYTHONPATH`` and ``LD_LIBRARY_PATH`` with the build in front of this process's."""
    install = where / "install"
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    site = install / "lib" / version / "site-packages"
    return {
        key: os.pathsep.join(filter(None, [str(path), os.environ.get(key)]))
        for key, path in (("PYTHONPATH", site), ("LD_LIBRARY_PATH", install / "lib"))
    }


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def build(*, force: bool = False) -> Path:
    """Build tf2_msgs unless done (one build at a time); return its ``prefix()``.

    Raises:
        BuildError: a tool is missing, or a step failed (the log's tail in the text).
    """
    where = prefix()
    with _locked(where.with_suffix(".lock")):
        if is_built(where) and not force:
            return where
        if missing := missing_tools():
            raise BuildError(f"missing: {', '.join(missing)} (apt-get install build-essential)")
        shutil.rmtree(where, ignore_errors=True)
        where.mkdir(parents=True)
        log = where / "build.log"
        try:
            _build(where, log)
        except subprocess.CalledProcessError as exc:
            tail = log.read_text("utf-8", "replace")[-4000:]
            raise BuildError(f"{exc.cmd[:3]} failed; {log}:\n{tail}") from None
        finally:
            for scratch in ("venv", "build"):  # the prefix stands alone; the log stays
                shutil.rmtree(where / scratch, ignore_errors=True)
        (where / "install" / DONE).write_text(time.strftime("%Y-%m-%dT%H:%M:%S\n"))
    return where


def _build(where: Path, log: Path) -> None:
    venv, source = where / "venv", where / "src" / "tf2_msgs"
    shutil.copytree(PACKAGE, source)
    shutil.copytree(MESSAGES, source / "msg", ignore=shutil.ignore_patterns("*.md"))
    python = venv / "bin" / "python"
    wheels = [*BUILD_WHEELS, *([] if shutil.which("cmake") else ["cmake"])]
    (where / "constraints.txt").write_text("\n".join(_pins()) + "\n")
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "VIRTUAL_ENV"}}
    env.update(
        PATH=os.pathsep.join([str(venv / "bin"), env.get("PATH", "")]),
        AMENT_PREFIX_PATH=str(venv),
        CMAKE_PREFIX_PATH=str(venv),
        PYTHONNOUSERSITE="1",
    )
    with open(log, "w") as out:
        start = time.monotonic()

        def run(*cmd: str | Path) -> None:
            out.write(f"$ [{time.monotonic() - start:.1f} s] {' '.join(map(str, cmd))}\n")
            out.flush()
            subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env, check=True)

        run(sys.executable, "-m", "venv", venv)
        pip = (python, "-m", "pip", "install", "-q", "--disable-pip-version-check")
        run(*pip, "-c", where / "constraints.txt", *wheels)
        _point_at_this_python(python, venv / "share")
        build_dir = where / "build"
        run(
            "cmake", "-S", source, "-B", build_dir, "-DBUILD_TESTING=OFF",
            "-DCMAKE_BUILD_TYPE=Release", f"-DCMAKE_INSTALL_PREFIX={where / 'install'}",
            f"-DPython3_EXECUTABLE={python}", "-DPython3_FIND_VIRTUALENV=ONLY",
        )  # fmt: skip
        run("cmake", "--build", build_dir, "--parallel", "2")
        run("cmake", "--install", build_dir)
        out.write(f"done in {time.monotonic() - start:.1f} s\n")


def _point_at_this_python(python: Path, share: Path) -> None:
    """Replace the wheel builder's Python and numpy include folders in the CMake exports."""
    query = "import numpy, sysconfig; print(sysconfig.get_paths()['include'], numpy.get_include())"
    found = subprocess.run([python, "-c", query], capture_output=True, text=True, check=True)
    python_include, numpy_include = found.stdout.split()
    site = r"lib/python3\.\d+/site-packages/"
    numpy_old = re.compile(BUILDER_PYTHON.pattern + site + r"numpy/_core/include")
    python_old = re.compile(BUILDER_PYTHON.pattern + r"include/python3\.\d+")
    for path in share.glob("*/cmake/*.cmake"):
        text = path.read_text("utf-8")
        if BUILDER_PYTHON.search(text):
            text = numpy_old.sub(numpy_include, text)
            path.write_text(python_old.sub(python_include, text), "utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", action="store_true", help="rebuild even if cached")
    force = parser.parse_args().force
    start = time.monotonic()
    try:
        where = build(force=force)
    except BuildError as exc:
        sys.exit(f"tf2_msgs build: {exc}")
    print(where / "install")
    print(f"{time.monotonic() - start:.1f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
