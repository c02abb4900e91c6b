"""``/docs`` (Swagger UI) and ``/redoc`` (ReDoc) render in real Chromium with nothing fetched
from another host, and the page's "API docs" link leads to this server's ``/docs``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.long]


def test_swagger_ui_renders_the_api_from_this_server(
    open_tab: Callable[..., Any], page_server: str
) -> None:
    # `open_tab` aborts and records any request that is not to page_server (or blob:/data:)
    tab = open_tab(page_server, "/docs", ready=".swagger-ui .info .title")
    assert "wavecore" in tab.inner_text(".swagger-ui .info .title")
    tab.wait_for_selector(".opblock-summary-path[data-path='/v1/images/encode']")
    assert not tab.problems, tab.problems


def test_redoc_renders_the_api_from_this_server(
    open_tab: Callable[..., Any], page_server: str
) -> None:
    tab = open_tab(page_server, "/redoc", ready="h1:has-text('wavecore')")
    tab.wait_for_selector('text="/v1/images/encode"')
    # ReDoc's menu always asks for Redocly's logo from their CDN: the server's policy blocks it
    # in the browser, so no request leaves (`open_tab` would have recorded one). The refusal
    # is logged; that one message is expected, nothing else may appear.
    logo = "'https://cdn.redoc.ly/redoc/logo-mini.svg'"

    def blocked_logo(problem: str) -> bool:
        return problem.startswith("console error") and logo in problem and "Policy" in problem

    tab.problems[:] = [p for p in tab.problems if not blocked_logo(p)]
    assert not tab.problems, tab.problems


def test_the_pages_api_docs_link_opens_the_local_docs(page: Any, page_server: str) -> None:
    page.click("text=API docs")
    page.wait_for_selector(".swagger-ui .info .title")
    assert page.url == page_server + "/docs"
    assert not page.problems, page.problems
