"""A headless browser on a page of the workflow: Debian's Chromium driven by Playwright.

Playwright's own browser builds are not downloaded: it drives the system's Chromium
(``apt-get install chromium``, which ``make setup`` does). WebGL runs on SwiftShader, the
software renderer, so the page draws on a machine without a GPU as on any other.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

CHROMIUM_NAMES = ("chromium", "chromium-browser")
FLAGS = (
    "--no-sandbox",  # root in a container has no user namespace for the sandbox
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",  # WebGL on the software renderer, as without a GPU
)


class BrowserError(RuntimeError):
    """No browser to drive (the message says what to install)."""


def chromium_path() -> str:
    """The system's Chromium.

    Raises:
        BrowserError: if none is installed.
    """
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    raise BrowserError("no Chromium on this machine: `make setup` installs Debian's `chromium`")


@contextmanager
def open_page(
    path: str | Path, width: int = 1280, height: int = 800, ready: str | None = None,
    timeout_ms: float = 60_000,
) -> Iterator[tuple[Any, list[str], list[str]]]:
    """A browser page on the file ``path`` (opened as ``file://``, no server).

    Args:
        path: the HTML file.
        width: the viewport's width, pixels.
        height: the viewport's height, pixels.
        ready: a JavaScript expression to wait for after loading (e.g. ``window.viewer.ready``).
        timeout_ms: how long to wait for it.

    Yields:
        ``(page, errors, requests)``: the Playwright page, the console errors and page errors
        seen so far, and every URL the page requested.
    """
    from playwright.sync_api import sync_playwright

    errors: list[str] = []
    requests: list[str] = []
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium_path(), args=list(FLAGS))
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("request", lambda r: requests.append(r.url))
            page.goto(Path(path).resolve().as_uri())
            if ready is not None:
                page.wait_for_function(ready, timeout=timeout_ms)
            yield page, errors, requests
        finally:
            browser.close()
