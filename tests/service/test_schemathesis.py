"""Schemathesis against the live server: every operation of the OpenAPI document, valid and
invalid requests (positive and negative modes), and not one 5xx.  Slow: run with ``-m slow``.

The schema is the app's own (``create_app().openapi()``, the same document /openapi.json
serves), so each operation and mode is one test; requests go to the real uvicorn process.
(schemathesis' own pytest plugin does not run under pytest 9: it sets ``Item._nodeid``.)
"""

from __future__ import annotations

from typing import Any

import pytest

schemathesis = pytest.importorskip("schemathesis", reason="the test extra is not installed")

from hypothesis import HealthCheck, given, settings  # noqa: E402
from schemathesis import GenerationMode  # noqa: E402

from service.app import create_app  # noqa: E402

pytestmark = pytest.mark.slow

SCHEMA = schemathesis.openapi.from_dict(create_app().openapi())
#: (path, method, mode): negative mode only where there is something to make invalid (an
#: operation without parameters or body has no invalid request: hypothesis finds none).
CASES = [
    pytest.param(path, method, mode, id=f"{method.upper()} {path} {mode.value}")
    for path, methods in SCHEMA.raw_schema["paths"].items()
    for method, spec in methods.items()
    for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE)
    if mode == GenerationMode.POSITIVE or spec.get("parameters") or spec.get("requestBody")
]


@pytest.mark.parametrize(("path", "method", "mode"), CASES)
def test_no_request_gets_a_5xx(live_server: str, path: str, method: str, mode: Any) -> None:
    operation = SCHEMA[path][method.upper()]
    failures: list[str] = []

    @settings(
        max_examples=150,
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(case=operation.as_strategy(generation_mode=mode))
    def run(case: Any) -> None:
        response = case.call(base_url=live_server, timeout=120)
        if response.status_code >= 500:
            failures.append(
                f"{response.status_code}: {response.text[:300]}\n  {case.as_curl_command()}"
            )

    run()
    assert not failures, "\n".join(failures[:5])
