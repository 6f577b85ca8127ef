"""``python -m rwt_ros2.build [--force] [PACKAGE ...]``: build interface packages for rclpy.

Each package (``tf2_msgs`` by default; those of ``rwt_ros2.interfaces.BUILDS``) is built
from the definitions rwt carries, or found in the cache, and its install prefix printed
(docs/ros2.md). ``rwt serve --ros2`` runs this command itself, in the background, the
first time it needs one of them; run it beforehand to have the package at once (a
robot's image, CI). No module of rwt imports this one.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from rwt_ros2.interfaces import BUILD_NICENESS, BUILD_TIMEOUT_S, InterfaceBuildError, build

__all__ = ["main"]


def main(argv: list[str] | None = None) -> None:
    """``python -m rwt_ros2.build``: build each package named (or found cached); print prefixes.

    Exits 1 with the reason (and the log's last lines) on stderr when a build fails.
    """
    parser = argparse.ArgumentParser(
        prog="python -m rwt_ros2.build",
        description="Build interface packages for rclpy from rwt's definitions (docs/ros2.md).",
    )
    parser.add_argument("packages", nargs="*", default=["tf2_msgs"], metavar="PACKAGE")
    parser.add_argument("--force", action="store_true", help="rebuild even if cached")
    parser.add_argument(
        "--timeout",
        type=float,
        default=BUILD_TIMEOUT_S,
        metavar="SECONDS",
        help=f"stop a build that runs longer (default {BUILD_TIMEOUT_S:.0f})",
    )
    args = parser.parse_args(argv)
    os.nice(BUILD_NICENESS)
    for package in args.packages:
        start = time.monotonic()
        try:
            where = build(package, force=args.force, timeout_s=args.timeout)
        except InterfaceBuildError as exc:
            tail = exc.log.read_text("utf-8", "replace")[-4000:] if exc.log is not None else ""
            sys.exit(f"{package}: {exc}\n{tail}".rstrip())
        print(where / "install", flush=True)  # noqa: T201 - the command's output
        took = time.monotonic() - start
        print(f"{package}: {took:.1f} s", file=sys.stderr)  # noqa: T201 - its report


if __name__ == "__main__":
    main()
