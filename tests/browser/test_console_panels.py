"""The console's Parameters and Plot tabs, driven by mouse and keyboard input (docs/console.md).

One embedded server (panels_robot.py: typed parameters of /robot, /odom and
/temperature at 20 Hz) and one page for the module; the scenarios run in order,
as a user would click through them. What is checked is what the user sees: the
inputs, the server's answers beside the buttons, the values the graph reads back,
the legend, and the CSV file Chromium downloads.
"""

from __future__ import annotations

import csv
import io
import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.integration.client_harness import ServerProcess

from .cdp import Browser, Page, wait_until
from .userinput import CTRL, click, click_until, press, type_into

ROW = '#param-editor tr[data-name="{}"]'
GRAPH_VALUE = '#params tr[data-name="{}"] td:last-child'


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    script = Path(__file__).with_name("panels_robot.py")
    process = ServerProcess(tmp_path_factory.mktemp("panels"), cmd=[sys.executable, str(script)])
    try:
        yield process.url.replace("ws://", "http://") + "/"
    finally:
        process.stop()


@pytest.fixture(scope="module")
def downloads(browser: Browser, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Where Chromium saves downloads, each under its guid (Browser.downloadProgress says)."""
    folder = tmp_path_factory.mktemp("downloads")
    browser.send(
        "Browser.setDownloadBehavior",
        behavior="allowAndName",
        downloadPath=str(folder),
        eventsEnabled=True,
    )
    return folder


@pytest.fixture(scope="module")
def page(browser: Browser, server: str) -> Iterator[Page]:
    page = browser.new_page()
    page.goto(server)
    page.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
    yield page
    page.close()


def status_of(page: Page, name: str) -> str:
    """The text beside the Set button of parameter ``name``, once it is an answer."""
    return str(
        page.wait_for(
            f"(t => t && t !== 'setting…' && t)"
            f"(document.querySelector('{ROW.format(name)} [role=status]').textContent)",
            what=f"the answer to setting {name}",
        )
    )


def set_by_click(page: Page, name: str) -> str:
    page.evaluate(f"document.querySelector('{ROW.format(name)} [role=status]').textContent = ''")
    click(page, f"{ROW.format(name)} button")
    return status_of(page, name)


def graph_shows(page: Page, name: str, text: str) -> None:
    """The graph's parameter list (read on its own at each refresh) shows ``text`` for
    ``name``. Each poll that does not see it presses Refresh, the refresh the 2 s timer
    runs (one at a time)."""
    shown = f"document.querySelector('{GRAPH_VALUE.format(name)}')?.textContent"
    page.wait_for(
        f"{shown} === {json.dumps(text)} || document.getElementById('refresh').click()",
        what=f"{name} = {text} in the graph",
    )


def test_parameters_get_inputs_that_fit_their_types(page: Page) -> None:
    click(page, '#tabs button[data-tab="params"]')
    page.wait_for(f"!!document.querySelector('{ROW.format('/robot:gains')} textarea')")
    kinds = page.evaluate(
        "Object.fromEntries([...document.querySelectorAll('#param-editor tbody tr')].map(r =>"
        " [r.dataset.name, (i => i && `${i.tagName.toLowerCase()}:${i.type}:${i.step ?? ''}`)"
        "(r.querySelector('.param-value').firstElementChild)]))"
    )
    assert kinds["/robot:verbose"] == "input:checkbox:"
    assert kinds["/robot:retries"] == "input:number:1"
    assert kinds["/robot:max_speed"] == "input:number:any"
    assert kinds["/robot:name"] == "input:text:"
    assert kinds["/robot:gains"] == "textarea:textarea:"
    value = f"document.querySelector('{ROW.format('{}')} .param-value').firstElementChild.value"
    assert page.evaluate(value.format("/robot:max_speed")) == "1.5"
    assert page.evaluate(value.format("/robot:name")) == "console-bot"
    assert json.loads(page.evaluate(value.format("/robot:gains"))) == [1.0, 2.0]


def test_sets_a_number_and_a_string_with_the_mouse(page: Page) -> None:
    type_into(page, f"{ROW.format('/robot:max_speed')} input", "2.25")
    assert set_by_click(page, "/robot:max_speed").startswith("set at")
    graph_shows(page, "/robot:max_speed", "2.25")
    type_into(page, f"{ROW.format('/robot:name')} input", "bot, two")
    assert set_by_click(page, "/robot:name").startswith("set at")
    graph_shows(page, "/robot:name", '"bot, two"')


def test_an_integer_is_checked_before_it_is_sent(page: Page) -> None:
    field = f"{ROW.format('/robot:retries')} input"
    type_into(page, field, "4.5")
    assert set_by_click(page, "/robot:retries") == "4.5 is not an integer"
    status = f"document.querySelector('{ROW.format('/robot:retries')} [role=status]')"
    assert page.evaluate(f"{status}.className") == "error"
    type_into(page, field, "7")
    press(page, "Enter", 13)  # Enter in the input sets it
    assert status_of(page, "/robot:retries").startswith("set at")
    graph_shows(page, "/robot:retries", "7")


def test_a_checkbox_is_set_from_the_keyboard(page: Page) -> None:
    box = f"{ROW.format('/robot:verbose')} input"
    page.evaluate(f"document.querySelector('{box}').focus()")
    press(page, " ", 32)  # Space toggles the focused checkbox
    assert page.evaluate(f"document.querySelector('{box}').checked")
    press(page, "Tab", 9)  # to the row's Set button
    assert (
        page.evaluate("document.activeElement.getAttribute('aria-label')") == "set /robot:verbose"
    )
    press(page, "Enter", 13)
    assert status_of(page, "/robot:verbose").startswith("set at")
    graph_shows(page, "/robot:verbose", "true")


def test_the_servers_refusal_is_shown_beside_the_button(page: Page) -> None:
    area = f"{ROW.format('/robot:gains')} textarea"
    type_into(page, area, '[1, "two"]')  # a ROS 2 array holds one type
    press(page, "Enter", 13, CTRL)
    text = status_of(page, "/robot:gains")
    assert text.startswith("refused: ") and "one type" in text, text
    type_into(page, area, "[0.5, 1, 2]")
    press(page, "Enter", 13, CTRL)
    assert status_of(page, "/robot:gains").startswith("set at")
    graph_shows(page, "/robot:gains", "[0.5, 1.0, 2.0]")
    type_into(page, f"{ROW.format('/robot:serial')} input", "X-2")
    assert set_by_click(page, "/robot:serial") == "refused: parameter /robot:serial is read-only"
    serial = f"document.querySelector('{ROW.format('/robot:serial')} input')"
    assert page.evaluate(f"{serial}.value") == "X-2"  # what was typed stays for another try
    click(page, "#param-reload")  # until Reload reads the server's value again
    page.wait_for(f"{serial}.value === 'X-1'", what="the read-only value read again")


def test_the_graph_filter_applies_to_the_parameters(page: Page) -> None:
    shown = (
        "[...document.querySelectorAll('#param-editor tbody tr')].filter(r => !r.hidden)"
        ".map(r => r.dataset.name)"
    )
    type_into(page, "#graph-filter", "speed")
    assert page.evaluate(shown) == ["/robot:max_speed"]
    type_into(page, "#graph-filter", "/robot:*s")
    assert sorted(page.evaluate(shown)) == ["/robot:gains", "/robot:retries"]
    type_into(page, "#graph-filter", "")
    assert len(page.evaluate(shown)) == 6


def legend(page: Page) -> list[str]:
    return page.evaluate(
        "[...document.querySelectorAll('#plot-legend li .plot-name')].map(n => n.textContent)"
    )


def test_plots_fields_of_two_topics_on_one_axis(page: Page) -> None:
    click(page, '#tabs button[data-tab="plot"]')
    type_into(page, '#plot-add input[name="topic"]', "/odom")
    type_into(page, '#plot-add input[name="field"]', "pose.pose.position.x")
    click(page, '#plot-add button[type="submit"]')
    assert legend(page) == ["/odom pose.pose.position.x"]
    # a second series from the echo view: its + beside the field
    click(page, '#topics tbody tr[data-name="/temperature"]')
    page.wait_for(  # the echo above the fields has stopped growing
        "document.querySelectorAll('#echo-output .message').length"
        " === Number(document.getElementById('echo-keep').value)",
        what="the echo to fill",
    )
    add = "#plot-fields button[aria-label='plot /temperature data on the Plot tab']"
    click_until(page, add, f"document.querySelector({json.dumps(add)}).textContent === '✓'", "✓")
    click(page, '#tabs button[data-tab="plot"]')
    assert legend(page) == ["/odom pose.pose.position.x", "/temperature data"]
    values = page.wait_for(
        "(v => v.every(t => t && !isNaN(Number(t))) && v)([...document.querySelectorAll("
        "'#plot-legend .plot-value')].map(n => n.textContent))",
        what="a value for each series",
    )
    assert -1 <= float(values[0]) <= 1 and float(values[1]) >= 20
    colours = page.evaluate(
        "[...document.querySelectorAll('#plot-legend .swatch')].map(s => s.style.backgroundColor)"
    )
    assert colours == ["rgb(43, 123, 214)", "rgb(214, 71, 43)"]

    def both_lines_drawn() -> bool:
        shot = Image.open(io.BytesIO(page.screenshot("#multi-plot"))).convert("RGB")
        rgb = np.asarray(shot).astype(int)
        r, b = rgb[..., 0], rgb[..., 2]
        return int(((b > 150) & (r < 100)).sum()) > 20 and int(((r > 150) & (b < 100)).sum()) > 20

    wait_until(both_lines_drawn, 10, "the /odom and /temperature lines")


def test_a_bad_series_is_refused_beside_add(page: Page) -> None:
    type_into(page, '#plot-add input[name="topic"]', "/nope")
    type_into(page, '#plot-add input[name="field"]', "data")
    press(page, "Enter", 13)  # submits the form
    assert page.text("#plot-add-result") == "no topic /nope in the graph"
    type_into(page, '#plot-add input[name="topic"]', "/temperature")
    press(page, "Enter", 13)
    assert page.text("#plot-add-result") == "/temperature data is plotted already"
    assert page.evaluate("document.getElementById('plot-add-result').className") == "error"


def download_csv(page: Page, downloads: Path) -> list[list[str]]:
    """Click CSV and read the file Chromium saved; checks the link it followed."""
    browser = page.browser
    done_before = len(browser.events(None, "Browser.downloadProgress"))
    click(page, "#plot-csv")

    def completed() -> str | None:
        events = browser.events(None, "Browser.downloadProgress")[done_before:]
        done = [e["params"]["guid"] for e in events if e["params"]["state"] == "completed"]
        return done[0] if done else None

    guid = wait_until(completed, 10, "the CSV download")
    begun = browser.events(None, "Browser.downloadWillBegin")
    assert [e["params"]["suggestedFilename"] for e in begun if e["params"]["guid"] == guid] == [
        "rwt-plot.csv"
    ]
    assert page.evaluate("document.getElementById('plot-download').href").startswith("blob:")
    return list(csv.reader(io.StringIO((downloads / guid).read_text(), newline="")))


def test_pause_and_csv_export(page: Page, downloads: Path) -> None:
    click(page, "#plot-pause")
    assert page.text("#plot-pause") == "Resume"
    first = download_csv(page, downloads)
    assert first[0] == ["time", "/odom pose.pose.position.x", "/temperature data"]
    rows = first[1:]
    assert len(rows) >= 2
    times = [float(row[0]) for row in rows]
    assert times == sorted(times) and times[-1] - times[0] <= 30  # the plot's window
    assert abs(times[-1] - time.time()) < 60  # seconds since the epoch, as received
    odom = [float(row[1]) for row in rows if row[1]]
    temperature = [float(row[2]) for row in rows if row[2]]
    assert odom and all(-1 <= x <= 1 for x in odom)
    assert temperature and all(t >= 20 for t in temperature)
    held = page.text("#plot-legend")
    time.sleep(0.3)  # six more messages of each topic arrive meanwhile; none is kept
    assert download_csv(page, downloads) == first
    assert page.text("#plot-legend") == held
    click(page, "#plot-pause")
    assert page.text("#plot-pause") == "Pause"
    page.wait_for(f"document.getElementById('plot-legend').textContent !== {json.dumps(held)}")
    # removing a series removes its column
    click(page, "#plot-legend button[aria-label='remove /odom pose.pose.position.x']")
    assert legend(page) == ["/temperature data"]
    assert download_csv(page, downloads)[0] == ["time", "/temperature data"]


def test_csv_rows_join_series_by_time_and_quote_names(page: Page) -> None:
    """The page's own csvText: one row per time, empty cells where a series has no point."""
    text = page.evaluate(
        "import('/console/plotpanel.js').then(m => m.csvText(["
        "['/a x,y', [[1.5, 1], [2, 2]]], ['/b \"q\"', [[2, 3.25]]]]))"
    )
    assert text == 'time,"/a x,y","/b ""q"""\r\n1.500,1,\r\n2.000,2,3.25\r\n'


def test_no_errors_in_the_page(page: Page) -> None:
    assert page.errors() == [], json.dumps(page.errors())
