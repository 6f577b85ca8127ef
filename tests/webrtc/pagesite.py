"""A local web site for the browser tests: generated pages, and tests/js/node_modules.

``serve_pages(page)`` serves ``page(path, query)``'s HTML where it returns some, and
the files of tests/js (``/node_modules/...``, or of another folder) elsewhere, with
the JavaScript type that module scripts need.
"""

from __future__ import annotations

import functools
import http.server
import threading
from contextlib import contextmanager
from typing import TYPE_CHECKING

from tests.support.realclients import REPO

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

MODULES = REPO / "tests" / "js" / "node_modules"


class _Site(http.server.SimpleHTTPRequestHandler):
    def __init__(
        self,
        *args: object,
        page: Callable[[str, str], str | None],
        folder: Path,
        **kwargs: object,
    ) -> None:
        self._page = page
        super().__init__(*args, directory=str(folder), **kwargs)  # type: ignore[arg-type]

    def do_GET(self) -> None:
        path, _, query = self.path.partition("?")
        html = self._page(path, query)
        if html is None:
            super().do_GET()
            return
        body = html.encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: object) -> None:
        pass  # the test's output is its assertions

    def guess_type(self, path: str | Path) -> str:
        if str(path).endswith((".js", ".mjs")):
            return "text/javascript"  # module scripts need a JavaScript type
        return super().guess_type(path)


@contextmanager
def serve_pages(
    page: Callable[[str, str], str | None], folder: Path | None = None
) -> Iterator[str]:
    """Serve the site on a free port of 127.0.0.1; yields its base URL.

    ``folder``: whose files are served where ``page`` gives none (default: tests/js).
    """
    handler = functools.partial(_Site, page=page, folder=folder or MODULES.parent)
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()
