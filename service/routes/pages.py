"""``GET /``: the upload page, ``service/static/index.html``.

The page is static HTML, CSS and JavaScript (no build step, nothing fetched from elsewhere);
``create_app`` serves the rest of ``service/static/`` under ``/static``.  The page only calls
the public ``/v1`` endpoints, so everything it does can also be done with curl.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse

router = APIRouter(tags=["pages"])

_INDEX = Path(__file__).resolve().parents[1] / "static" / "index.html"

# Only this server: scripts, styles and requests. Images also come from blob: URLs (the
# reconstructions) and data: (the empty favicon).
_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
    "connect-src 'self' blob:; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)


# HEAD too: link checkers and load balancers probe pages with it.
@router.api_route(
    "/", methods=["GET", "HEAD"], response_class=FileResponse, include_in_schema=False
)
async def index() -> FileResponse:
    return FileResponse(
        _INDEX,
        media_type="text/html; charset=utf-8",
        headers={"Content-Security-Policy": _CSP, "Cache-Control": "no-cache"},
    )
