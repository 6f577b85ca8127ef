"""Build an interface package for rclpy from the definitions rwt carries (docs/ros2.md).

The command ``python -m rwt_ros2.build [--force] [PACKAGE ...]`` (``rwt_ros2.build``)
runs ``build`` for each package (``tf2_msgs`` by default) and prints each install prefix.

rclpy carries a type only with its generated package (C type support and the Python
classes), and PyPI's ROS 2 Kilted wheels have none for some packages rwt needs:
``tf2_msgs``, whose ``TFMessage`` carries ``/tf`` and ``/tf_static``. They do have the
rosidl generators and ament_cmake, so this builds the package from rwt's own text
(``rwt_graph/interfaces/<package>/msg``, ``BUILDS``):

1. a venv of this Python with the generators, pinned to the ROS 2 wheels installed
   here (same versions, so the built libraries fit the runtime rclpy loads);
2. the wheels' exported CMake targets name the wheel builder's Python and numpy include
   folders (``/opt/python/cp311-cp311/...``): pointed at this venv's, in the venv;
3. ``cmake`` configure, build (2 jobs), install into the prefix.

It needs a C and C++ compiler and make (``apt-get install build-essential``), the
Python headers, cmake 3.20+ (PyPI's ``cmake`` wheel is taken when there is none) and
PyPI (or the index pip is set up for). The prefix is cached by a key of everything the
build reads (``cache_root``: ``RWT_ROS2_BUILD_DIR``, else ``$XDG_CACHE_HOME/rwt``, else
``~/.cache/rwt``); a second call finds it. On a 2-core machine the build of
``tf2_msgs`` takes 30-60 s (about half of it pip), and the prefix is under 1 MB. It runs
at a lower CPU priority (``BUILD_NICENESS``) and within ``BUILD_TIMEOUT_S``.

``rwt serve --ros2`` runs that command itself, in the background, the first time it
needs a package of ``BUILDS`` that rclpy cannot import (``rwt_ros2.ondemand``), and
loads a finished build into its own process (``load``); ``runtime_env`` says what
another process (an rclpy node of your own) needs to import it.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import importlib
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

from rwt_protocol.errors import RwtError

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = [
    "BUILDS",
    "BUILD_NICENESS",
    "BUILD_TIMEOUT_S",
    "COMMAND",
    "InterfaceBuildError",
    "build",
    "cache_root",
    "cached",
    "is_built",
    "load",
    "missing_tools",
    "prefix",
    "runtime_env",
]

INTERFACES = Path(__file__).resolve().parent.parent / "rwt_graph" / "interfaces"
"""rwt's interface text (``rwt_graph/interfaces``), the source of each build."""

BUILDS: dict[str, tuple[str, ...]] = {"tf2_msgs": ("geometry_msgs",)}
"""The packages rwt builds for rclpy when it needs them and rclpy cannot import them
(PyPI has no Kilted wheel of them), with the packages their messages use (each a
``ros-kilted-*`` wheel): only their messages (``msg/``) are built."""

COMMAND = "python -m rwt_ros2.build"
"""The command that builds them (``rwt serve --ros2`` runs it when it needs to)."""

BUILD_TIMEOUT_S = 600.0
"""The longest one build may take by default, seconds (``build``'s ``timeout_s``; the
link's ``Ros2Options.build_timeout_s``): past it the build is stopped and fails, and
``rwt serve --ros2`` goes on without the package."""

BUILD_NICENESS = 10
"""How much lower the build's CPU priority is than its caller's (``os.nice``): a server
building beside its clients gives them the CPU first."""

#: What the build venv holds beyond the message packages the package depends on.
_GENERATORS = (
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
)
#: The tools the build runs that no wheel brings.
TOOLS = ("cc", "c++", "make")
DONE = ".rwt-built"
BUILDER_PYTHON = re.compile(r"/opt/python/cp3\d+-cp3\d+/")

_CMAKELISTS = """\
# {package} for rclpy from rwt's message text (rwt_ros2.build writes this file).
cmake_minimum_required(VERSION 3.20)
project({package})
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
{find_dependencies}
file(GLOB messages RELATIVE "${{CMAKE_CURRENT_SOURCE_DIR}}"
     "${{CMAKE_CURRENT_SOURCE_DIR}}/msg/*.msg")
rosidl_generate_interfaces(${{PROJECT_NAME}} ${{messages}} DEPENDENCIES {dependencies})
ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""

_PACKAGE_XML = """\
<?xml version="1.0"?>
<!-- {package} for rclpy, built by rwt_ros2.build from the message text rwt carries
     (rwt_graph/interfaces/{package}/msg): PyPI has no ROS 2 Kilted wheel of it. -->
<package format="3">
  <name>{package}</name>
  <version>0.0.0</version>
  <description>{package}'s messages, built by rwt for rclpy</description>
  <maintainer email="rwt@example.invalid">rwt</maintainer>
  <license>BSD-3-Clause</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
{depends}
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""


class InterfaceBuildError(RwtError, RuntimeError):
    """The build cannot run or failed (also a RuntimeError).

    Attributes:
        reason: what went wrong, in one line.
        log: the build's log, when it got that far.
    """

    def __init__(self, reason: str, log: Path | None = None) -> None:
        super().__init__(reason if log is None else f"{reason}; its log: {log}")
        self.reason = reason
        self.log = log


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


def _sources(package: str) -> dict[str, str]:
    """The files of the package's source folder: relative path -> text.

    Raises:
        InterfaceBuildError: ``package`` is not one of ``BUILDS``.
    """
    if package not in BUILDS:
        known = ", ".join(sorted(BUILDS))
        raise InterfaceBuildError(f"rwt builds only {known} for rclpy, not {package}")
    dependencies = BUILDS[package]
    files = {
        "CMakeLists.txt": _CMAKELISTS.format(
            package=package,
            find_dependencies="\n".join(f"find_package({d} REQUIRED)" for d in dependencies),
            dependencies=" ".join(dependencies),
        ),
        "package.xml": _PACKAGE_XML.format(
            package=package, depends="\n".join(f"  <depend>{d}</depend>" for d in dependencies)
        ),
    }
    for path in sorted((INTERFACES / package / "msg").glob("*.msg")):
        files[f"msg/{path.name}"] = path.read_text("utf-8")
    return files


def cache_root() -> Path:
    """Where builds are kept: ``RWT_ROS2_BUILD_DIR``, ``$XDG_CACHE_HOME/rwt``, ``~/.cache/rwt``."""
    named = os.environ.get("RWT_ROS2_BUILD_DIR")
    if named:
        return Path(named)
    cache = os.environ.get("XDG_CACHE_HOME")
    return (Path(cache) if cache else Path.home() / ".cache") / "rwt"


def prefix(package: str = "tf2_msgs") -> Path:
    """Where the build of ``package`` for this Python, these wheels and this text is (built or not).

    Raises:
        InterfaceBuildError: ``package`` is not one of ``BUILDS``.
    """
    digest = hashlib.sha256()
    for name, text in _sources(package).items():
        digest.update(name.encode() + b"\0" + text.encode() + b"\0")
    digest.update("\n".join([sys.version, *_GENERATORS, *_pins()]).encode())
    return cache_root() / f"{package}-{digest.hexdigest()[:16]}"


def is_built(where: Path) -> bool:
    """Whether ``where`` (a ``prefix()``) holds a finished build."""
    return (where / "install" / DONE).is_file()


def cached(package: str) -> Path | None:
    """The finished build of ``package`` in the cache, None when there is none yet."""
    where = prefix(package)
    return where if is_built(where) else None


def _site_packages(where: Path) -> Path:
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    return where / "install" / "lib" / version / "site-packages"


def runtime_env(where: Path) -> dict[str, str]:
    """``PYTHONPATH`` and ``LD_LIBRARY_PATH`` with the build in front of this process's."""
    return {
        key: os.pathsep.join(filter(None, [str(path), os.environ.get(key)]))
        for key, path in (
            ("PYTHONPATH", _site_packages(where)),
            ("LD_LIBRARY_PATH", where / "install" / "lib"),
        )
    }


def load(where: Path) -> None:
    """Make a finished build importable in this process, as ``runtime_env`` does for a new one.

    The dynamic loader reads ``LD_LIBRARY_PATH`` only when a process starts, so the
    build's libraries are loaded here first (each found again by its name when the
    Python extension or rmw asks for it), and the variable is set for the type support
    lookups that read it later.

    Raises:
        InterfaceBuildError: a library does not load.
    """
    lib = where / "install" / "lib"
    pending = sorted(lib.glob("*.so"))
    while pending:  # in an order where each one's dependencies loaded before it
        failed: list[Path] = []
        errors: list[str] = []
        for path in pending:
            try:
                ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
            except OSError as exc:
                failed.append(path)
                errors.append(str(exc))
        if len(failed) == len(pending):
            raise InterfaceBuildError(f"the build in {where} does not load: {errors[0]}")
        pending = failed
    os.environ["LD_LIBRARY_PATH"] = runtime_env(where)["LD_LIBRARY_PATH"]
    site = str(_site_packages(where))
    if site not in sys.path:
        sys.path.append(site)
    importlib.invalidate_caches()


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def build(
    package: str = "tf2_msgs", *, force: bool = False, timeout_s: float = BUILD_TIMEOUT_S
) -> Path:
    """Build ``package`` unless done (one build of it at a time); return its ``prefix()``.

    Args:
        package: one of ``BUILDS``.
        force: build again even when the cache has it.
        timeout_s: the longest the steps may take together once the build holds its
            lock (a step still running then is stopped).

    Raises:
        InterfaceBuildError: a tool is missing, a step failed or ran past ``timeout_s`` (the
            log's path in the error).
    """
    where = prefix(package)
    with _locked(where.with_suffix(".lock")):
        if is_built(where) and not force:
            return where
        if missing := missing_tools():
            named = ", ".join(missing)
            raise InterfaceBuildError(f"missing {named} (apt-get install build-essential)")
        shutil.rmtree(where, ignore_errors=True)
        where.mkdir(parents=True)
        log = where / "build.log"
        try:
            _build(package, where, log, time.monotonic() + timeout_s)
        except subprocess.CalledProcessError as exc:
            raise InterfaceBuildError(f"`{_shown(exc.cmd)}` failed", log) from None
        except subprocess.TimeoutExpired as exc:
            took = f"ran past {timeout_s:g} s"
            raise InterfaceBuildError(f"`{_shown(exc.cmd)}` {took}", log) from None
        finally:
            for scratch in ("venv", "build"):  # the prefix stands alone; the log stays
                shutil.rmtree(where / scratch, ignore_errors=True)
        (where / "install" / DONE).write_text(time.strftime("%Y-%m-%dT%H:%M:%S\n"))
    return where


def _shown(cmd: object) -> str:
    """A failed step's command, short: its first words."""
    words = cmd if isinstance(cmd, list | tuple) else [cmd]
    return " ".join(map(str, words[:4]))


def _build(package: str, where: Path, log: Path, deadline: float) -> None:
    venv, source = where / "venv", where / "src" / package
    for name, text in _sources(package).items():
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        (source / name).write_text(text, "utf-8")
    python = venv / "bin" / "python"
    wheels = [
        *_GENERATORS,
        *(f"ros-kilted-{d.replace('_', '-')}" for d in BUILDS[package]),
        *([] if shutil.which("cmake") else ["cmake"]),
    ]
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
            subprocess.run(
                cmd,
                stdout=out,
                stderr=subprocess.STDOUT,
                env=env,
                check=True,
                timeout=max(0.1, deadline - time.monotonic()),
            )

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
