"""Files Foxglove clients fetch by ``package://`` URI: meshes, textures, robot descriptions.

Foxglove's 3D panel loads a URDF's meshes with ``fetchAsset`` (docs/foxglove.md).
``package://PKG/PATH`` names the file PATH inside the package PKG, found as ROS
finds packages:

1. in the package directories the operator names (``rwt serve --package-path
   DIR``, then the ``ROS_PACKAGE_PATH`` entries): ``DIR/PKG`` if it is a
   directory, else a directory under DIR (up to ``_SCAN_DEPTH`` levels down)
   whose ``package.xml`` names PKG;
2. in the share directory of an installed ROS 2 package: ``PREFIX/share/PKG``
   for each ``PREFIX`` of ``AMENT_PREFIX_PATH``.

Refused (an error response, never a crash): another scheme, a PATH that is
empty, absolute or has an empty, ``.`` or ``..`` segment, a backslash or a
control character, a file type outside ``ASSET_SUFFIXES`` (foxglove_bridge's
default list), a symbolic link that leads out of the package's directory, what
is not a regular file, and a file over ``MAX_ASSET_BYTES``. Error texts name the
URI, never a path of the server's disk.
"""

from __future__ import annotations

import logging
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Final

from rwt_protocol.errors import RemoteProtocolError

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence

__all__ = [
    "ASSET_SUFFIXES",
    "MAX_ASSET_BYTES",
    "MAX_ASSET_URI",
    "AssetError",
    "AssetRoots",
]

logger = logging.getLogger("rwt.foxglove")

MAX_ASSET_BYTES: Final = 32 * 1024 * 1024
"""The largest file served as an asset, bytes (docs/limits.md)."""
MAX_ASSET_URI: Final = 4096
"""The longest ``fetchAsset`` URI read, characters."""
ASSET_SUFFIXES: Final = frozenset(
    {
        ".dae",
        ".fbx",
        ".glb",
        ".gltf",
        ".jpeg",
        ".jpg",
        ".mtl",
        ".obj",
        ".png",
        ".stl",
        ".tif",
        ".tiff",
        ".urdf",
        ".webp",
        ".xacro",
    }
)
"""File types served (lower case): meshes, textures and robot descriptions."""
_SCHEME: Final = "package://"
_PACKAGE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
_SCAN_DEPTH: Final = 4  # levels under a package path searched for package.xml
_SCAN_DIRS: Final = 20_000  # directories looked at per package path, at most
_XML_NAME = re.compile(rb"<name>\s*([^<\s]+)\s*</name>")


class AssetError(RemoteProtocolError):
    """A ``fetchAsset`` that cannot be answered with data; its text goes to the client."""


@dataclass(frozen=True)
class AssetRoots:
    """Where ``package://`` URIs are looked up.

    Attributes:
        package_paths: directories holding packages, searched first, in order.
        prefixes: install prefixes whose ``share/PKG`` directories are packages.
    """

    package_paths: Sequence[Path] = ()
    prefixes: Sequence[Path] = ()
    _scanned: dict[str, Path] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        for root in self.package_paths:  # once: packages found by their package.xml
            for name, path in _scan(root):
                self._scanned.setdefault(name, path)

    @classmethod
    def from_environment(
        cls, package_paths: Iterable[Path], environ: Mapping[str, str]
    ) -> AssetRoots | None:
        """The operator's directories, then ``ROS_PACKAGE_PATH``'s, then ``AMENT_PREFIX_PATH``'s.

        Returns:
            The roots, or None when there is none (no assets to serve).
        """
        paths = [*package_paths, *_listed(environ.get("ROS_PACKAGE_PATH", ""))]
        prefixes = _listed(environ.get("AMENT_PREFIX_PATH", ""))
        paths = [p for p in paths if p.is_dir()]
        prefixes = [p for p in prefixes if (p / "share").is_dir()]
        if not paths and not prefixes:
            return None
        return cls(tuple(paths), tuple(prefixes))

    def package(self, name: str) -> Path | None:
        """The directory of package ``name``, or None."""
        for root in self.package_paths:
            if (root / name).is_dir():
                return root / name
        found = self._scanned.get(name)
        if found is not None:
            return found
        for prefix in self.prefixes:
            if (prefix / "share" / name).is_dir():
                return prefix / "share" / name
        return None

    def resolve(self, uri: str) -> Path:
        """The file ``uri`` names, checked as the module says.

        Raises:
            AssetError: a refused URI, or no such package or file.
        """
        package, relative = _parse(uri)
        root = self.package(package)
        shown = _shown(uri)
        if root is None:
            raise AssetError(f"{shown}: no package {package!r} here")
        real_root = root.resolve()
        try:
            real = (root / relative).resolve(strict=True)
        except (OSError, RuntimeError):  # missing, or a symlink loop
            raise AssetError(f"{shown}: no such file") from None
        if not real.is_relative_to(real_root):
            raise AssetError(f"{shown}: a link out of the package is not followed")
        return real

    def read(self, uri: str) -> bytes:
        """The bytes of the file ``uri`` names (reads the disk: call it off the event loop).

        Raises:
            AssetError: as ``resolve``; not a regular file, over ``MAX_ASSET_BYTES``,
                or unreadable.
        """
        path = self.resolve(uri)
        shown = _shown(uri)
        # non-blocking: opening a FIFO must not wait for a writer; no link at the end
        # (resolved above): one put there since is not followed
        flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOFOLLOW", 0)
        try:
            fd = os.open(path, flags)
        except OSError as exc:
            raise AssetError(f"{shown}: cannot be read ({exc.strerror})") from None
        try:
            info = os.fstat(fd)
            if not stat.S_ISREG(info.st_mode):
                raise AssetError(f"{shown}: not a file")
            if info.st_size > MAX_ASSET_BYTES:
                raise AssetError(f"{shown}: larger than {MAX_ASSET_BYTES} bytes")
            with os.fdopen(fd, "rb") as file:
                fd = -1  # the file owns it now
                data = file.read(MAX_ASSET_BYTES + 1)  # it may have grown since
        except OSError as exc:
            raise AssetError(f"{shown}: cannot be read ({exc.strerror})") from None
        finally:
            if fd >= 0:
                os.close(fd)
        if len(data) > MAX_ASSET_BYTES:
            raise AssetError(f"{shown}: larger than {MAX_ASSET_BYTES} bytes")
        return data


def _parse(uri: str) -> tuple[str, str]:
    """``package://PKG/PATH`` as ``(PKG, PATH)``.

    Raises:
        AssetError: not such a URI, or a PATH that could leave the package.
    """
    shown = _shown(uri)
    if len(uri) > MAX_ASSET_URI:
        raise AssetError(f"{shown}: longer than {MAX_ASSET_URI} characters")
    if not uri.startswith(_SCHEME):
        raise AssetError(f"{shown}: only package:// URIs are served")
    if any(ord(ch) < 0x20 or ch in "\\\x7f" for ch in uri):
        raise AssetError(f"{shown}: a backslash or control character")
    package, _, relative = uri[len(_SCHEME) :].partition("/")
    if not _PACKAGE_NAME.fullmatch(package) or package in (".", ".."):
        raise AssetError(f"{shown}: not a package name")
    segments = relative.split("/")
    if not relative or any(s in ("", ".", "..") for s in segments):
        raise AssetError(f"{shown}: the path must be relative, without empty, . or .. parts")
    if Path(segments[-1]).suffix.lower() not in ASSET_SUFFIXES:
        raise AssetError(f"{shown}: not a mesh, texture or robot description file")
    return package, relative


def _shown(uri: str) -> str:
    """``uri`` as error texts show it: printable, at most 200 characters."""
    text = "".join(ch if ch.isprintable() else "?" for ch in uri[:200])
    return text + ("..." if len(uri) > 200 else "")


def _listed(value: str) -> list[Path]:
    """The paths of a ``PATH``-like variable, empty entries left out."""
    return [Path(part) for part in value.split(os.pathsep) if part]


def _scan(root: Path) -> list[tuple[str, Path]]:
    """The packages under ``root``: directories with a ``package.xml``, by its name.

    Breadth first, ``_SCAN_DEPTH`` levels, at most ``_SCAN_DIRS`` directories; a
    package's own subdirectories, hidden ones and ones with ``COLCON_IGNORE`` or
    ``CATKIN_IGNORE`` are not searched.
    """
    found: list[tuple[str, Path]] = []
    level = [root]
    seen = 0
    for _ in range(_SCAN_DEPTH + 1):
        below: list[Path] = []
        for directory in level:
            seen += 1
            if seen > _SCAN_DIRS:
                logger.warning("event=asset_scan_cut root=%s dirs=%d", root, _SCAN_DIRS)
                return found
            manifest = directory / "package.xml"
            if manifest.is_file():
                found.append((_package_name(manifest) or directory.name, directory))
                continue
            if (directory / "COLCON_IGNORE").exists() or (directory / "CATKIN_IGNORE").exists():
                continue
            try:
                children = sorted(directory.iterdir())
            except OSError:
                continue
            below += [c for c in children if not c.name.startswith(".") and _is_dir(c)]
        level = below
    return found


def _is_dir(path: Path) -> bool:
    try:
        return path.is_dir() and not path.is_symlink()
    except OSError:
        return False


def _package_name(manifest: Path) -> str | None:
    """The ``<name>`` of a package.xml (its first 64 KiB), or None."""
    try:
        with manifest.open("rb") as file:
            head = file.read(64 * 1024)
    except OSError:
        return None
    match = _XML_NAME.search(head)
    return match.group(1).decode("utf-8", "replace") if match else None
