"""The console's files as ``ConsoleSite`` answers them: known paths only, no traversal."""

from __future__ import annotations

import json
import re
from importlib import resources

import pytest

from rwt_console import ConsoleSite

STATIC = resources.files("rwt_console").joinpath("static")


def headers(reply) -> dict[str, str]:
    return dict(reply.headers)


@pytest.mark.parametrize("path", ["/", "/console/", "/console", "/?x=1"])
def test_the_page_is_at_the_root_and_under_console(path: str) -> None:
    reply = ConsoleSite().answer("GET", path)
    assert reply.status == 200
    assert headers(reply)["Content-Type"] == "text/html; charset=utf-8"
    assert b"<title>rwt console</title>" in reply.body


def test_the_video_port_keeps_its_root() -> None:
    site = ConsoleSite(root_is_console=False)
    assert not site.handles("/")
    assert site.handles("/console/main.js")
    assert site.answer("GET", "/console/").status == 200


@pytest.mark.parametrize(
    ("name", "kind"),
    [("main.js", "text/javascript"), ("console.css", "text/css"), ("index.html", "text/html")],
)
def test_files_have_their_content_type(name: str, kind: str) -> None:
    reply = ConsoleSite().answer("GET", f"/console/{name}")
    assert reply.status == 200
    assert headers(reply)["Content-Type"].startswith(kind)
    assert reply.body == STATIC.joinpath(name).read_bytes()
    assert headers(reply)["X-Content-Type-Options"] == "nosniff"
    assert headers(reply)["Cache-Control"] == "no-cache"
    assert "script-src 'self'" in headers(reply)["Content-Security-Policy"]


@pytest.mark.parametrize(
    "path",
    [
        "/console/../site.py",
        "/console/..%2fsite.py",
        "/console/%2e%2e/site.py",
        "/console/static/main.js",
        "/console//etc/passwd",
        "/console/site.py",
        "/console/__init__.py",
        "/etc/passwd",
        "/console/main.js/",
        "/console/MAIN.JS",
    ],
)
def test_anything_else_is_404(path: str) -> None:
    reply = ConsoleSite().answer("GET", path)
    assert reply.status == 404
    assert reply.body.startswith(b"404 ")


def test_only_get_and_head() -> None:
    site = ConsoleSite()
    reply = site.answer("POST", "/")
    assert reply.status == 405
    assert headers(reply)["Allow"] == "GET, HEAD"
    head = site.answer("HEAD", "/console/main.js")
    assert head.status == 200
    assert head.body == b""
    assert headers(head)["Content-Length"] == str(len(STATIC.joinpath("main.js").read_bytes()))


def test_config_tells_the_page_where_the_rest_is() -> None:
    site = ConsoleSite(websocket_path="/ws", websocket_tls=True, auth=True)
    site.video_port = 8081  # rwt serve sets it once the video server listens
    site.video_token = True  # and this with --auth-secret-file
    reply = site.answer("GET", "/console/config.json")
    assert headers(reply)["Content-Type"] == "application/json"
    assert json.loads(reply.body) == {
        "websocket": {"port": None, "path": "/ws", "tls": True},
        "video": {"port": 8081, "token": True},
        "auth": True,
        "foxglove": False,
        "limits": {},
    }


def test_every_module_the_page_loads_is_served() -> None:
    """No CDN, no missing file: every script, style and import resolves to a served file."""
    site = ConsoleSite()
    page = site.answer("GET", "/").body.decode()
    wanted = set(re.findall(r'(?:src|href)="(/console/[^"]+)"', page))
    assert "/console/main.js" in wanted
    assert not re.search(r'(?:src|href)="(?:https?:)?//', page)  # nothing from elsewhere
    seen: set[str] = set()
    while wanted:
        path = wanted.pop()
        seen.add(path)
        reply = site.answer("GET", path)
        assert reply.status == 200, path
        if path.endswith(".js"):
            text = reply.body.decode()
            assert "http://" not in text.replace("`http://${", "")  # only the video port, built
            for module in re.findall(r"from '\./([\w-]+\.js)'", text):
                if f"/console/{module}" not in seen:
                    wanted.add(f"/console/{module}")
    js = {p.name for p in STATIC.iterdir() if p.name.endswith(".js")}
    assert {path.removeprefix("/console/") for path in seen if path.endswith(".js")} == js
