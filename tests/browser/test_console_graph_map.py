"""The console's Node graph and Map tabs against an embedded server with a map, TF and
named nodes (mapped_robot.py), driven with real mouse and keyboard input over CDP.

One browser, one server and one page for the module (docs/console.md).
"""

from __future__ import annotations

import base64
import io
import json
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from PIL import Image

from tests.integration.client_harness import ServerProcess

from .cdp import Browser, Page, wait_until
from .mapped_robot import (
    FREE_CELL,
    HALF_CELL,
    HEIGHT,
    OCCUPIED_CELL,
    ORIGIN,
    RESOLUTION,
    SENSORS,
    UNKNOWN_CELL,
    WIDTH,
)

ITEM = "#node-graph g[data-kind={}][data-name={}]"
CANVAS = "#map-canvas"
MAGENTA = (224, 0, 224)  # the robot's arrow
FIT = 0.9  # a fitted map fills 90% of the canvas
ZOOM_STEP = 1.25


@pytest.fixture(scope="module")
def page(browser: Browser, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Page]:
    script = Path(__file__).with_name("mapped_robot.py")
    process = ServerProcess(tmp_path_factory.mktemp("mapped"), cmd=[sys.executable, str(script)])
    page = browser.new_page()
    try:
        page.goto(process.url.replace("ws://", "http://") + "/")
        page.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
        yield page
    finally:
        page.close()
        process.stop()


def item(kind: str, name: str) -> str:
    return ITEM.format(kind, json.dumps(name))


def centre(page: Page, selector: str) -> tuple[float, float]:
    """The middle of an element in the viewport, scrolled into view first."""
    x, y = page.evaluate(
        f"(e => {{ e.scrollIntoView({{block: 'center', inline: 'center'}});"
        " const r = e.getBoundingClientRect(); return [r.x + r.width / 2, r.y + r.height / 2]; })"
        f"(document.querySelector({json.dumps(selector)}))"
    )
    return x, y


def mouse(page: Page, kind: str, x: float, y: float, **more: object) -> None:
    page.send("Input.dispatchMouseEvent", type=kind, x=x, y=y, **more)


def click(page: Page, selector: str) -> None:
    """A real click (pointer down and up) in the middle of the element."""
    page.wait_for(f"!!document.querySelector({json.dumps(selector)})", what=selector)
    x, y = centre(page, selector)
    mouse(page, "mouseMoved", x, y)
    mouse(page, "mousePressed", x, y, button="left", buttons=1, clickCount=1)
    mouse(page, "mouseReleased", x, y, button="left", buttons=0, clickCount=1)


def shown(page: Page, kind: str) -> list[str]:
    """The names the graph shows as text, of its nodes or its topics."""
    names: list[str] = page.evaluate(
        f"[...document.querySelectorAll('#node-graph g[data-kind={kind}]')]"
        ".map(g => g.querySelector('text').textContent)"
    )
    return names


def test_the_node_graph_draws_nodes_topics_and_their_edges(page: Page) -> None:
    click(page, '#tabs button[data-tab="node-graph"]')
    page.wait_for(f"!!document.querySelector('{item('node', '/base')}')", what="the node graph")
    sensors = [f"/sensor_{i:02d}" for i in range(SENSORS)]
    expected = ["/talker", "/listener", "/map_server", "/static_tf", "/odometry", "/amcl"]
    expected += ["/fusion", "/base"]
    # not rwt's own nodes, nor this page's: a first draw may come before the page knows
    # its own node's name, so the refreshes are waited for (each poll presses Refresh)
    page.wait_for(
        f"(() => {{ const want = {json.dumps(sorted({*expected, *sensors}))};"
        " const got = [...document.querySelectorAll('#node-graph g[data-kind=node]')]"
        ".map(g => g.querySelector('text').textContent).sort();"
        " return JSON.stringify(got) === JSON.stringify(want)"
        " || (document.getElementById('refresh').click(), false); })()",
        what="the robot's nodes alone",
    )
    nodes = shown(page, "node")
    assert set(nodes) == {*expected, *sensors}
    topics = shown(page, "topic")
    assert {"/chatter", "/map", "/tf", "/tf_static", "/cmd_vel", "/sensors/s07"} <= set(topics)
    assert "/rosout" not in topics and "/client_count" not in topics  # debug, hidden
    pairs = [
        ("/talker", "/chatter"),
        ("/chatter", "/listener"),
        ("/sensor_07", "/sensors/s07"),
        ("/sensors/s07", "/fusion"),
        ("/fusion", "/cmd_vel"),
        ("/cmd_vel", "/base"),
        ("/base", "/odom"),
        ("/odom", "/fusion"),  # closes a cycle: drawn back to the left
        ("/map_server", "/map"),
    ]
    for source, target in pairs:
        source_kind, target_kind = ("node", "topic") if source in nodes else ("topic", "node")
        # the curve leaves the right side of its source and ends at the left side of its target
        ends = page.evaluate(
            f"""(() => {{
            const path = document.querySelector(
              '#node-graph path[data-from="{source}"][data-to="{target}"]');
            if (!path) return null;
            const m = path.getScreenCTM();
            const a = path.getPointAtLength(0).matrixTransform(m);
            const b = path.getPointAtLength(path.getTotalLength()).matrixTransform(m);
            const s = document.querySelector('{item(source_kind, source)}').getBoundingClientRect();
            const t = document.querySelector('{item(target_kind, target)}').getBoundingClientRect();
            const middle = (r) => (r.top + r.bottom) / 2;
            return [a.x - s.right, a.y - middle(s), b.x - t.left, b.y - middle(t)];
            }})()"""
        )
        assert ends is not None, f"no edge {source} -> {target}"
        assert all(abs(d) < 8 for d in ends), (source, target, ends)
    unrelated = '#node-graph path[data-from="/talker"][data-to="/cmd_vel"]'
    assert page.evaluate(f"document.querySelector('{unrelated}')") is None


def test_the_layout_is_layered_and_nothing_overlaps(page: Page) -> None:
    """Publishers left of their topics, subscribers right (but for the edge that closes
    the cycle fusion -> cmd_vel -> base -> odom -> fusion), and ~50 nodes readable."""
    found = page.evaluate(
        """(() => {
        const boxes = [...document.querySelectorAll('#node-graph g[data-kind]')]
          .map(g => [g.dataset.name, g.getBoundingClientRect()]);
        const overlaps = [];
        for (let i = 0; i < boxes.length; i += 1) for (let j = i + 1; j < boxes.length; j += 1) {
          const [a, r] = boxes[i]; const [b, s] = boxes[j];
          const apart = r.right <= s.left || s.right <= r.left
            || r.bottom <= s.top || s.bottom <= r.top;
          if (!apart) overlaps.push([a, b]);
        }
        const backwards = [...document.querySelectorAll('#node-graph path[data-key]')].filter(p => {
          const [from, to] = p.dataset.key.split('>');
          const x = (id) => document.querySelector(`#node-graph g[data-id="${CSS.escape(id)}"]`)
            .getBoundingClientRect().left;
          return x(from) >= x(to);
        }).map(p => p.dataset.key);
        return {count: boxes.length, overlaps, backwards};
        })()"""
    )
    assert found["count"] > 2 * SENSORS
    assert found["overlaps"] == []
    assert found["backwards"] == ["t:/odom>n:/fusion"]


def test_hide_debug_off_shows_rwts_nodes_this_page_and_debug_topics(page: Page) -> None:
    click(page, "#node-graph-hide-debug")
    page.wait_for(f"!!document.querySelector('{item('node', '/rosapi')}')", what="rwt's nodes")
    assert "/rosout" in shown(page, "topic")
    # this page's own node subscribes to the latched client count
    page.wait_for(
        "[...document.querySelectorAll('#node-graph path[data-from=\"/client_count\"]')]"
        ".some(p => p.dataset.to.startsWith('/rwt_client_'))",
        what="an edge from /client_count to this page's node",
    )
    click(page, "#node-graph-hide-debug")
    page.wait_for(
        f"!document.querySelector('{item('node', '/rosapi')}')", what="rwt's nodes hidden"
    )


def test_refreshes_keep_the_items_and_their_places(page: Page) -> None:
    page.evaluate(
        "window.keptItems = [...document.querySelectorAll("
        " '#node-graph g[data-kind], #node-graph path')];"
        " window.keptPlaces = window.keptItems.map(e =>"
        " e.getAttribute('transform') ?? e.getAttribute('d'));"
        " window.keptRound = Number(document.getElementById('node-graph').dataset.rounds)"
    )
    page.wait_for(  # each poll presses Refresh, the refresh the 2 s timer runs (one at a time)
        "Number(document.getElementById('node-graph').dataset.rounds) >= window.keptRound + 2"
        " || document.getElementById('refresh').click()",
        what="two refreshes of the node graph",
    )
    assert page.evaluate(
        "window.keptItems.every((e, i) => e.isConnected"
        " && (e.getAttribute('transform') ?? e.getAttribute('d')) === window.keptPlaces[i])"
    )


def test_a_topic_of_the_graph_opens_its_echo(page: Page) -> None:
    click(page, item("topic", "/chatter"))
    page.wait_for(
        "document.getElementById('topic-name').textContent === '/chatter'"
        " && /hello \\d+/.test(document.getElementById('echo-output').textContent)",
        what="the echo of /chatter",
    )
    # and with the keyboard: Enter on a focused topic
    click(page, '#tabs button[data-tab="node-graph"]')
    page.evaluate(f"document.querySelector('{item('topic', '/cmd_vel')}').focus()")
    page.press("Enter", 13)
    page.wait_for(
        "document.getElementById('topic-name').textContent === '/cmd_vel'"
        " && !document.getElementById('tab-topic').hidden",
        what="/cmd_vel chosen with Enter",
    )


# ---- the map ---------------------------------------------------------------------


def fitted_pixel(x: float, y: float) -> tuple[float, float]:
    """Where the fitted view draws map point (x, y) m on the 640 x 480 canvas (y up)."""
    width, height = WIDTH * RESOLUTION, HEIGHT * RESOLUTION
    scale = FIT * min(640 / width, 480 / height)
    centre_x, centre_y = ORIGIN[0] + width / 2, ORIGIN[1] + height / 2
    return 320 + (x - centre_x) * scale, 240 - (y - centre_y) * scale


def cell_pixel(column: int, row: int) -> tuple[float, float]:
    return fitted_pixel(
        ORIGIN[0] + (column + 0.5) * RESOLUTION, ORIGIN[1] + (row + 0.5) * RESOLUTION
    )


def canvas_shot(page: Page) -> Image.Image:
    """The pixels the canvas shows (its own 640 x 480, whatever its size on the page; no
    screenshot, which would scroll the page under the pointer)."""
    url = page.evaluate(f"document.querySelector('{CANVAS}').toDataURL('image/png')")
    return Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB")


def colour_at(page: Page, point: tuple[float, float]) -> tuple[int, int, int]:
    return canvas_shot(page).getpixel((round(point[0]), round(point[1])))  # type: ignore[return-value]


def near(colour: tuple[int, ...], wanted: tuple[int, ...], slack: int = 6) -> bool:
    return all(abs(a - b) <= slack for a, b in zip(colour, wanted, strict=True))


def arrow_at(page: Page, point: tuple[float, float], heading: tuple[int, int] = (0, -1)) -> bool:
    """The robot's arrow at `point`, its head 18 px along `heading` on the canvas (up: +y
    in the map), nothing 16 px behind it."""
    shot = canvas_shot(page)
    x, y = round(point[0]), round(point[1])
    dx, dy = heading
    return (
        near(shot.getpixel((x, y)), MAGENTA, 40)  # type: ignore[arg-type]
        and near(shot.getpixel((x + 18 * dx, y + 18 * dy)), MAGENTA, 40)  # type: ignore[arg-type]
        and not near(shot.getpixel((x - 16 * dx, y - 16 * dy)), MAGENTA, 40)  # type: ignore[arg-type]
    )


def grey_run(page: Page, y: float, x: float) -> list[int]:
    """The left and right ends of the run of 50% grey pixels through (x, y) on the canvas."""
    shot = canvas_shot(page)
    row = round(y)

    def grey(at: int) -> bool:
        return 0 <= at < 640 and near(shot.getpixel((at, row)), (128, 128, 128))  # type: ignore[arg-type]

    left = right = round(x)
    if not grey(left):
        return [-1, -1]
    while grey(left - 1):
        left -= 1
    while grey(right + 1):
        right += 1
    return [left, right + 1]


def canvas_to_viewport(page: Page, point: tuple[float, float]) -> tuple[float, float]:
    """Where the pointer goes for canvas pixel `point` (inside the canvas' border)."""
    left, top, scale = page.evaluate(
        f"(c => {{ const r = c.getBoundingClientRect();"
        " return [r.left + c.clientLeft, r.top + c.clientTop, c.clientWidth / c.width]; })"
        f"(document.querySelector('{CANVAS}'))"
    )
    return left + point[0] * scale, top + point[1] * scale


ROBOT = fitted_pixel(1.5, 1.0)  # map -> odom (1, 0.5), odom -> base_link (0.5, 0.5) turned 90°


def test_the_map_shows_its_cells_where_its_origin_and_resolution_put_them(page: Page) -> None:
    click(page, '#tabs button[data-tab="map"]')
    page.wait_for(
        "document.getElementById('map-info').textContent.startsWith('map 40 \\u00d7 30 cells')",
        what="the latched map",
    )
    cells = {UNKNOWN_CELL: 205, OCCUPIED_CELL: 0, HALF_CELL: 128, FREE_CELL: 255}

    def drawn() -> bool:
        shot = canvas_shot(page)
        return all(
            near(shot.getpixel(tuple(round(v) for v in cell_pixel(*cell))), (grey,) * 3)  # type: ignore[arg-type]
            for cell, grey in cells.items()
        )

    wait_until(drawn, 10, "the map's cells in their colours")
    # the map's corner cell (0, 0) is at the bottom left: y goes up
    bottom_left = cell_pixel(0, 0)
    assert bottom_left[0] < 320 and bottom_left[1] > 240
    assert near(colour_at(page, cell_pixel(10, 1)), (0, 0, 0))  # occupied row 1, not row 28
    assert near(colour_at(page, cell_pixel(10, HEIGHT - 2)), (255, 255, 255))


def test_the_robot_arrow_is_where_tf_puts_base_link(page: Page) -> None:
    wait_until(lambda: arrow_at(page, ROBOT), 10, "the robot's arrow at base_link")
    info = page.text("#map-info")
    assert "robot base_link at (1.50, 1.00) m, heading 90° in map" in info, info


def choose(page: Page, selector: str, value: str) -> None:
    """Set a select or an input and fire its change, as picking or typing and leaving would."""
    page.evaluate(
        f"(e => {{ e.value = {json.dumps(value)}; e.dispatchEvent(new Event('change')); }})"
        f"(document.querySelector({json.dumps(selector)}))"
    )


def test_the_robot_pose_from_a_pose_stamped_topic_in_another_frame(page: Page) -> None:
    """/robot_pose is in odom: the arrow is where map -> odom puts it, heading +x."""
    choose(page, "#map-pose-kind", "topic")
    choose(page, "#map-pose", "/robot_pose")
    wait_until(
        lambda: arrow_at(page, fitted_pixel(1.5, 0.0), (1, 0)), 10, "the arrow of /robot_pose"
    )
    assert "robot /robot_pose at (1.50, 0.00) m, heading 0° in map" in page.text("#map-info")
    choose(page, "#map-pose", "/nowhere")
    page.wait_for(
        "document.getElementById('map-info').textContent.includes('no pose of /nowhere in map yet')"
    )
    choose(page, "#map-pose-kind", "frame")
    choose(page, "#map-pose", "base_link")
    wait_until(lambda: arrow_at(page, ROBOT), 10, "the arrow back at base_link")


def test_a_topic_that_is_not_a_map_says_so_beside_the_map(page: Page) -> None:
    choose(page, "#map-topic", "/chatter")
    text = page.wait_for(
        "(t => t && t)(document.getElementById('map-error').textContent)", what="the error"
    )
    assert text.startswith("/chatter: not a map"), text
    choose(page, "#map-topic", "/map")
    page.wait_for("document.getElementById('map-error').textContent === ''")
    page.wait_for("document.getElementById('map-info').textContent.startsWith('map 40 \\u00d7 30')")


def test_drag_pans_and_the_wheel_zooms_about_the_pointer(page: Page) -> None:
    page.evaluate(f"document.querySelector('{CANVAS}').scrollIntoView({{block: 'center'}})")
    start = canvas_to_viewport(page, (320, 240))
    end = (start[0] + 60, start[1] + 40)
    mouse(page, "mouseMoved", *start)
    mouse(page, "mousePressed", *start, button="left", buttons=1, clickCount=1)
    mouse(page, "mouseMoved", *end, button="left", buttons=1)
    mouse(page, "mouseReleased", *end, button="left", buttons=0, clickCount=1)
    scale = page.evaluate(f"(c => c.width / c.clientWidth)(document.querySelector('{CANVAS}'))")
    moved = (ROBOT[0] + 60 * scale, ROBOT[1] + 40 * scale)
    wait_until(lambda: arrow_at(page, moved), 10, "the arrow moved with the drag")
    # a wheel notch over the robot: the robot stays, the map grows around it
    # the 50% block of cells: its left and right edges, panned, then zoomed about the robot
    edges = [fitted_pixel(ORIGIN[0] + c * RESOLUTION, 0)[0] + 60 * scale for c in (30, 35)]
    row = cell_pixel(*HALF_CELL)[1] + 40 * scale
    assert grey_run(page, row, (edges[0] + edges[1]) / 2) == pytest.approx(edges, abs=2)
    mouse(page, "mouseWheel", *canvas_to_viewport(page, moved), deltaX=0, deltaY=-100)
    zoomed = [moved[0] + (x - moved[0]) * ZOOM_STEP for x in edges]
    row = moved[1] + (row - moved[1]) * ZOOM_STEP
    wait_until(
        lambda: grey_run(page, row, (zoomed[0] + zoomed[1]) / 2) == pytest.approx(zoomed, abs=2),
        10,
        "the grey cells grown around the pointer",
    )
    assert arrow_at(page, moved)


def test_the_keyboard_fits_pans_and_zooms(page: Page) -> None:
    page.evaluate(f"document.querySelector('{CANVAS}').focus()")
    page.press("0", 48)
    wait_until(lambda: arrow_at(page, ROBOT), 10, "the fitted view again")
    page.press("ArrowRight", 39)  # the view goes right: the map moves 40 px left
    left = (ROBOT[0] - 40, ROBOT[1])
    wait_until(lambda: arrow_at(page, left), 10, "the arrow 40 px left")
    page.press("+", 187)  # about the canvas' centre
    zoomed = (320 + (left[0] - 320) * ZOOM_STEP, 240 + (left[1] - 240) * ZOOM_STEP)
    wait_until(lambda: arrow_at(page, zoomed), 10, "the arrow after zooming in")
    assert page.errors() == []
