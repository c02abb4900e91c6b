"""``GET /redoc``: ReDoc, with its script from this server and nothing loaded from elsewhere.

``/docs`` (Swagger UI) and the files of both (``/static-offline-docs/``) come from
``fastapi_offline.FastAPIOffline`` (see ``create_app``). Its ``/redoc`` is replaced by this
one, which adds a Content-Security-Policy: ReDoc's menu always shows Redocly's logo from their
CDN, and the policy keeps the browser from fetching it (the image hides itself when it cannot
load), so the page makes no request to another host.
"""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.openapi.docs import get_redoc_html
from fastapi.responses import HTMLResponse

router = APIRouter(tags=["pages"])

# Where FastAPIOffline mounts the Swagger UI and ReDoc files (its default ``static_url``).
DOCS_ASSETS = "/static-offline-docs"

# ReDoc renders with inline styles and runs its search in a blob: worker.
_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline' blob:; "
    "style-src 'self' 'unsafe-inline'; img-src 'self' data:; font-src 'self' data:; "
    "worker-src 'self' blob:; connect-src 'self'; object-src 'none'; base-uri 'none'"
)


@router.get("/redoc", response_class=HTMLResponse, include_in_schema=False)
async def redoc(request: Request) -> HTMLResponse:
    root = request.scope.get("root_path", "")
    page = get_redoc_html(
        openapi_url=f"{root}{request.app.openapi_url}",
        title=f"{request.app.title} - ReDoc",
        redoc_js_url=f"{root}{DOCS_ASSETS}/redoc.standalone.js",
        redoc_favicon_url=f"{root}{DOCS_ASSETS}/favicon.png",
        with_google_fonts=False,
    )
    page.headers["Content-Security-Policy"] = _CSP
    return page
