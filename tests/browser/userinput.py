"""A user's mouse and keyboard through Chromium's input pipeline (CDP ``Input.*``).

``Page.click`` and ``Page.fill`` call the DOM (``element.click()``, ``value =``);
these go the way a person's input goes: a mouse press and release at the element's
centre (focus, ``mousedown``, ``click``, a checkbox toggling), text inserted where
the caret is, keys with their modifiers. An element covered by another one, or
outside the window, does not get the click, as it would not for a user.
"""

from __future__ import annotations

import json

from .cdp import CdpError, Page

CTRL = 2  # Input.dispatchKeyEvent's modifiers bit for Control


def click(page: Page, selector: str) -> None:
    """Press and release the left button at the centre of ``selector`` (scrolled into view).

    Waits until the element stays put over two animation frames: a page still laying
    out (an echo growing above a button) would move it from under the pointer. It must
    also still be the one the selector finds, in the page, and the topmost element at its
    centre: a view that renders again as messages come (a table of fields beside an
    echo) replaces its buttons, and a replaced one has no box at all.
    """
    x, y = page.wait_for(
        f"(async () => {{ const sel = {json.dumps(selector)};"
        " const e = document.querySelector(sel);"
        " if (!e) return null; e.scrollIntoView({block: 'center'});"
        " const box = () => JSON.stringify(e.getBoundingClientRect());"
        " const before = box();"
        " for (let i = 0; i < 2; i++) await new Promise(requestAnimationFrame);"
        " if (box() !== before || !e.isConnected || document.querySelector(sel) !== e)"
        " return null;"
        " const r = e.getBoundingClientRect(), x = r.x + r.width / 2, y = r.y + r.height / 2;"
        " const hit = document.elementFromPoint(x, y);"
        " return r.width && r.height && hit && e.contains(hit) ? [x, y] : null; })()",
        what=f"{selector} to be still",
    )
    page.send("Input.dispatchMouseEvent", type="mouseMoved", x=x, y=y)
    for kind in ("mousePressed", "mouseReleased"):
        page.send("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)


def click_until(page: Page, selector: str, expression: str, what: str, tries: int = 3) -> None:
    """Click ``selector`` until ``expression`` holds, as a user clicks again when nothing happened.

    On a page that renders as messages come, a layout change between the pointer's aim and
    its press (an echo row of another height prepended above a button) can make a click
    land beside its target; on a loaded machine that happens now and then.

    Raises:
        CdpError: ``expression`` still falsy after ``tries`` clicks, 2 s apart.
    """
    for attempt in range(tries):
        click(page, selector)
        try:
            page.wait_for(expression, timeout_s=2.0, what=what)
            return
        except CdpError:
            if attempt == tries - 1:
                raise


def type_into(page: Page, selector: str, text: str) -> None:
    """Click ``selector``, select what it holds (Ctrl+A) and type ``text`` over it."""
    click(page, selector)
    for kind in ("keyDown", "keyUp"):
        page.send(
            "Input.dispatchKeyEvent",
            type=kind,
            key="a",
            code="KeyA",
            windowsVirtualKeyCode=65,
            modifiers=CTRL,
            commands=["selectAll"] if kind == "keyDown" else [],
        )
    page.send("Input.insertText", text=text)


def press(page: Page, key: str, code: int, modifiers: int = 0) -> None:
    """Press and release ``key`` (``Enter``, ``Tab``...) on the focused element."""
    text = {"Enter": "\r"}.get(key)
    for kind in ("keyDown", "keyUp"):
        params: dict[str, object] = {
            "type": kind,
            "key": key,
            "code": key,
            "windowsVirtualKeyCode": code,
            "modifiers": modifiers,
        }
        if kind == "keyDown" and text and not modifiers:
            params["text"] = text
        page.send("Input.dispatchKeyEvent", **params)
