"""Assets: ``package://`` URIs resolved in package directories, and the session's requests.

The files are real files in a temporary tree; what a client sees is checked on
the session's frames (fetch asset responses, opcode 0x04).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import pytest

from rwt_foxglove.assetrequests import MAX_PENDING_ASSETS
from rwt_foxglove.assets import MAX_ASSET_BYTES, AssetError, AssetRoots
from rwt_graph.graph import Graph

from .test_session import Client

MESH = b"solid cube\nendsolid cube\n"


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    """Package paths and an install prefix::

    ws/src/robot_description/meshes/base.stl    (a directory named as its package)
    ws/src/repo/arm/package.xml                  (<name>arm_description</name>)
    ws/src/repo/arm/meshes/link.dae
    ws/src/robot_description/urdf/robot.urdf
    ws/src/robot_description/meshes/inside.stl  -> base.stl (a link inside)
    ws/src/robot_description/meshes/escape.stl  -> outside/secret.stl
    prefix/share/installed_pkg/meshes/part.obj
    outside/secret.stl
    """
    desc = tmp_path / "ws" / "src" / "robot_description"
    (desc / "meshes").mkdir(parents=True)
    (desc / "meshes" / "base.stl").write_bytes(MESH)
    (desc / "urdf").mkdir()
    (desc / "urdf" / "robot.urdf").write_text("<robot name='r'/>")
    (desc / "notes.txt").write_text("not an asset")
    arm = tmp_path / "ws" / "src" / "repo" / "arm"
    (arm / "meshes").mkdir(parents=True)
    (arm / "package.xml").write_text("<package>\n  <name> arm_description </name>\n</package>\n")
    (arm / "meshes" / "link.dae").write_bytes(b"<COLLADA/>")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.stl").write_bytes(b"secret")
    (desc / "meshes" / "inside.stl").symlink_to("base.stl")
    (desc / "meshes" / "escape.stl").symlink_to(outside / "secret.stl")
    (desc / "meshes" / "folder.stl").mkdir()
    os.mkfifo(desc / "meshes" / "pipe.stl")  # opening it must not wait for a writer
    share = tmp_path / "prefix" / "share" / "installed_pkg" / "meshes"
    share.mkdir(parents=True)
    (share / "part.obj").write_bytes(b"v 0 0 0\n")
    return tmp_path


def roots(tree: Path) -> AssetRoots:
    found = AssetRoots.from_environment(
        [tree / "ws" / "src"], {"AMENT_PREFIX_PATH": f"{tree / 'nowhere'}:{tree / 'prefix'}"}
    )
    assert found is not None
    return found


def test_files_of_named_scanned_and_installed_packages_are_read(tree: Path) -> None:
    assets = roots(tree)
    assert assets.read("package://robot_description/meshes/base.stl") == MESH
    assert assets.read("package://robot_description/urdf/robot.urdf") == b"<robot name='r'/>"
    assert assets.read("package://arm_description/meshes/link.dae") == b"<COLLADA/>"
    assert assets.read("package://installed_pkg/meshes/part.obj") == b"v 0 0 0\n"
    assert assets.read("package://robot_description/meshes/inside.stl") == MESH


def test_ros_package_path_is_read_and_nothing_configured_is_none(tree: Path) -> None:
    found = AssetRoots.from_environment([], {"ROS_PACKAGE_PATH": str(tree / "ws" / "src")})
    assert found is not None
    assert found.read("package://robot_description/meshes/base.stl") == MESH
    assert AssetRoots.from_environment([], {}) is None
    assert AssetRoots.from_environment([tree / "missing"], {"AMENT_PREFIX_PATH": "/nope"}) is None


@pytest.mark.parametrize(
    ("uri", "reason"),
    [
        ("file:///etc/passwd", "only package:// URIs"),
        ("http://example.com/a.stl", "only package:// URIs"),
        ("package://robot_description/../../outside/secret.stl", "without empty, . or .."),
        ("package://robot_description/meshes/../meshes/base.stl", "without empty, . or .."),
        ("package://robot_description//etc/passwd.stl", "without empty, . or .."),
        ("package:///etc/passwd.stl", "not a package name"),
        ("package://../outside/secret.stl", "not a package name"),
        ("package://robot_description", "without empty, . or .."),
        ("package://robot_description/meshes\\base.stl", "backslash or control"),
        ("package://robot_description/meshes/base.stl\x00.png", "backslash or control"),
        ("package://robot_description/notes.txt", "not a mesh, texture"),
        ("package://robot_description/meshes/escape.stl", "a link out of the package"),
        ("package://robot_description/meshes/folder.stl", "not a file"),
        ("package://robot_description/meshes/pipe.stl", "not a file"),
        ("package://robot_description/meshes/none.stl", "no such file"),
        ("package://no_such_pkg/a.stl", "no package 'no_such_pkg'"),
        ("package://robot_description/" + "a/" * 3000 + "b.stl", "longer than 4096"),
    ],
)
def test_refused(tree: Path, uri: str, reason: str) -> None:
    with pytest.raises(AssetError) as caught:
        roots(tree).read(uri)
    assert reason in str(caught.value)
    assert str(tree) not in str(caught.value)  # never a path of the server's disk


def test_a_file_over_the_limit_is_refused(tree: Path) -> None:
    big = tree / "ws" / "src" / "robot_description" / "meshes" / "big.stl"
    with big.open("wb") as file:
        file.truncate(MAX_ASSET_BYTES + 1)  # sparse: no disk used
    with pytest.raises(AssetError, match=f"larger than {MAX_ASSET_BYTES} bytes"):
        roots(tree).read("package://robot_description/meshes/big.stl")


def responses(client: Client) -> list[tuple[int, int, str, bytes]]:
    """(request id, status, error, data) of the fetch asset responses so far."""
    client.drain()
    out = []
    for frame in client.binary:
        assert frame[0] == 4
        request_id, status, length = struct.unpack_from("<IBI", frame, 1)
        error = frame[10 : 10 + length].decode()
        out.append((request_id, status, error, frame[10 + length :]))
    client.binary = []
    return out


def test_without_assets_the_op_is_refused_with_a_status() -> None:
    client = Client(Graph())
    assert "assets" not in client.ops[0]["capabilities"]  # type: ignore[operator]
    client.send({"op": "fetchAsset", "uri": "package://a/b.stl", "requestId": 1})
    (status,) = client.take_ops("status")
    assert status["message"] == "op 'fetchAsset' is not supported by this server"


def test_requests_wait_in_order_and_one_file_is_read_and_queued_at_a_time(tree: Path) -> None:
    client = Client(Graph(), assets=roots(tree), run_jobs=False)
    assert "assets" in client.ops[0]["capabilities"]  # type: ignore[operator]
    session = client.session
    for n in (1, 2):
        client.send(
            {
                "op": "fetchAsset",
                "uri": f"package://robot_description/meshes/{n}.stl",
                "requestId": n,
            }
        )
    first = session.jobs.take_background()
    assert first is not None and session.jobs.take_background() is None  # one file at a time
    session.finish_job(first, MESH, 0.0)  # read (as the runtime's worker thread would)
    assert session.jobs.take_background() is None  # its response is not taken yet
    assert responses(client) == [(1, 0, "", MESH)]
    second = session.jobs.take_background()  # taken: the next one is read
    assert second is not None
    try:
        second.run()
    except AssetError as exc:
        session.finish_job(second, exc, 0.0)
    assert responses(client) == [
        (2, 1, "package://robot_description/meshes/2.stl: no such file", b"")
    ]
    assert session.jobs.take_background() is None


def test_a_closed_session_drops_its_requests_and_the_file_read_for_it(tree: Path) -> None:
    client = Client(Graph(), assets=roots(tree), run_jobs=False)
    session = client.session
    client.send(
        {"op": "fetchAsset", "uri": "package://robot_description/meshes/base.stl", "requestId": 1}
    )
    client.send(
        {"op": "fetchAsset", "uri": "package://robot_description/meshes/base.stl", "requestId": 2}
    )
    job = session.jobs.take_background()
    assert job is not None
    session.close()
    session.finish_job(job, job.run(), 0.0)  # the read ends after the close: nothing is kept
    assert session.frames_to_send() == [] and session.jobs.take_background() is None


def test_too_many_waiting_requests_are_answered_at_once(tree: Path) -> None:
    client = Client(Graph(), assets=roots(tree), run_jobs=False)
    for n in range(MAX_PENDING_ASSETS + 2):  # one is being read, 64 wait
        client.send({"op": "fetchAsset", "uri": "package://p/a.stl", "requestId": n})
    ((request_id, status, error, _),) = responses(client)
    assert (request_id, status) == (MAX_PENDING_ASSETS + 1, 1)
    assert error == f"more than {MAX_PENDING_ASSETS} asset requests wait: ask again later"


@pytest.mark.parametrize(
    ("op", "message"),
    [
        ({"op": "fetchAsset", "uri": "package://p/a.stl", "requestId": 2**32}, "request id"),
        ({"op": "fetchAsset", "uri": "package://p/a.stl"}, "fetchAsset: Object missing"),
        ({"op": "fetchAsset", "uri": 5, "requestId": 1}, "fetchAsset: Expected `str`"),
    ],
)
def test_a_malformed_fetch_asset_gets_an_error_status(
    tree: Path, op: dict[str, object], message: str
) -> None:
    client = Client(Graph(), assets=roots(tree), run_jobs=False)
    client.send(op)
    (status,) = client.take_ops("status")
    assert status["level"] == 2 and message in str(status["message"])
    assert client.session.jobs.take_background() is None
