"""``/docs`` and ``/redoc`` need nothing from another host (the browser check, which also
renders them, is tests/browser/test_docs.py in the ``long`` run)."""

from __future__ import annotations

import re

import httpx
import pytest

pytestmark = pytest.mark.anyio


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
async def test_docs_pages_load_their_files_from_this_server(
    client: httpx.AsyncClient, path: str
) -> None:
    r = await client.get(path)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    # every src/href (scripts, styles, icon) is a path on this server, never an absolute URL
    links = re.findall(r"""(?:src|href)\s*=\s*["']([^"']+)["']""", html)
    assert links, html
    assert not [link for link in links if not link.startswith("/")], links
    assert "fonts.googleapis" not in html and "cdn." not in html
    scripts = [link for link in links if link.endswith(".js")]
    assert scripts
    for link in links:
        asset = await client.get(link)
        assert asset.status_code == 200, link
        assert len(asset.content) > 1000, link  # the real bundle, not an error page
    # the page's own schema, which both UIs render
    assert "/openapi.json" in html
    if path == "/redoc":
        # ReDoc's menu asks for a logo from a CDN; the policy keeps the browser from it
        assert "img-src 'self' data:;" in r.headers["content-security-policy"]
