"""``GET /healthz`` and ``GET /metrics`` (Prometheus text format)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

import wavecore

from ..schemas import Health

router = APIRouter(tags=["operations"])


@router.get("/healthz", summary="Liveness and readiness")
async def healthz() -> Health:
    """Answers at once, even while every worker thread is busy (it does no coding)."""
    return Health(version=wavecore.__version__)


@router.get(
    "/metrics",
    response_class=Response,
    summary="Prometheus metrics",
    responses={200: {"content": {CONTENT_TYPE_LATEST: {}}}},
)
async def metrics(request: Request) -> Response:
    """Requests by route, method and status; durations; body bytes in and out; problems by
    kind; requests in flight; bytes of answers held while clients read them."""
    state = request.app.state
    state.metrics.in_flight.set(state.pool.in_use)
    state.metrics.answer_bytes.set(state.pool.answers.held)
    return Response(generate_latest(state.metrics.registry), media_type=CONTENT_TYPE_LATEST)
