"""Fixtures for the upload page in real headless Chromium.

The browser is Debian's ``/usr/bin/chromium`` driven by Playwright's Python package (Playwright's
own browser download is never used: it cannot reach the internet here, and CI installs Chromium
from apt in ``scripts/run.sh test``). The server is the suite's real uvicorn process on 127.0.0.1
(``live_server``), and ``small_limit_server`` is a second one with a 100 kB upload limit (both
in tests/conftest.py).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

CHROMIUM = os.environ.get("WAVECORE_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts" / "browser"


def _require_chromium() -> None:
    if Path(CHROMIUM).exists():
        return
    msg = f"{CHROMIUM} is missing: `bash scripts/run.sh test` installs it as root (apt chromium)"
    if os.environ.get("CI"):
        pytest.fail(msg)
    pytest.skip(msg)


@pytest.fixture(scope="session")
def page_server(live_server: str) -> str:
    """Base URL of the suite's real uvicorn process (``live_server`` in tests/conftest.py)."""
    return live_server


@pytest.fixture(scope="module")
def browser_context(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """One Chromium with a fresh profile per test module.

    Not per session: Playwright's sync API keeps an event loop running in this thread while it
    is open, and the async tests collected after these ones need the thread's loop free.
    """
    _require_chromium()
    from playwright.sync_api import sync_playwright

    profile = tmp_path_factory.mktemp("chromium-profile")
    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(profile),
            executable_path=CHROMIUM,
            args=CHROMIUM_ARGS,
            headless=True,
            viewport={"width": 1280, "height": 900},
            accept_downloads=True,
        )
        try:
            yield context
        finally:
            context.close()
    shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="session")
def artifacts() -> Path:
    """Screenshots for a person to look at (git-ignored)."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    return ARTIFACTS


@pytest.fixture
def open_tab(browser_context: Any) -> Iterator[Callable[..., Any]]:
    """Opens a fresh tab on ``<url><path>`` (the page by default) and waits for ``ready``; at
    the end, fails the test on any script error or any request that went off that server."""
    opened: list[Any] = []

    def open_(base: str, path: str = "/", ready: str = "body[data-ready='true']") -> Any:
        tab = browser_context.new_page()
        tab.set_viewport_size({"width": 1280, "height": 900})
        tab.set_default_timeout(60_000)  # the machine may be busy
        problems: list[str] = []
        tab.on("pageerror", lambda exc: problems.append(f"script error: {exc}"))
        tab.on(
            "console",
            lambda msg: (
                problems.append(f"console error: {msg.text}") if msg.type == "error" else None
            ),
        )

        def only_this_server(route: Any) -> None:
            url = route.request.url
            if url.startswith((base, "blob:", "data:")):
                route.continue_()
            else:
                problems.append(f"request off the server: {url}")
                route.abort()

        tab.route("**/*", only_this_server)
        tab.goto(base + path)
        tab.wait_for_selector(ready)
        tab.problems = problems
        opened.append(tab)
        return tab

    yield open_
    for tab in opened:
        tab.close()
    # A shown error response also logs "Failed to load resource" in the console; nothing else
    # may appear there.
    for tab in opened:
        assert not [p for p in tab.problems if "Failed to load resource" not in p], tab.problems


@pytest.fixture
def page(open_tab: Callable[..., Any], page_server: str) -> Any:
    """A fresh tab on the page served by the suite's server."""
    return open_tab(page_server)
