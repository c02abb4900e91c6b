"""Bad input gets an RFC 9457 problem with the right status and type, never a 500."""
# ruff: noqa: E501  (the table of bad inputs reads best one case per line)

from __future__ import annotations

import asyncio
import io
from collections.abc import Callable
from typing import Any

import httpx
import numpy as np
import pytest
from service_helpers import bomb_png, image_file, test_image

import wavecore
from service.routes import curves as curves_route

pytestmark = pytest.mark.anyio

PNG = image_file(test_image((40, 52)))
JPEG = image_file(test_image((40, 52, 3)), "JPEG", quality=90)
IMAGE_BUNDLE = wavecore.encode_image(test_image((40, 52)), quality=35)
CURVE_BUNDLE = wavecore.encode_curve(np.random.default_rng(1).random((30, 2)))


def _flipped(data: bytes, at: int) -> bytes:
    out = bytearray(data)
    out[at] ^= 0x5A
    return bytes(out)


def _npy(array: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, array, allow_pickle=True)
    return out.getvalue()


def image(data: bytes, name: str = "in.png", **fields: str) -> dict[str, Any]:
    return {"files": {"file": (name, data, "image/png")}, "data": fields}


def raw_json(text: str) -> dict[str, Any]:
    return {"content": text.encode(), "headers": {"content-type": "application/json"}}


def surface_npy(data: bytes, **fields: str) -> dict[str, Any]:
    return {"files": {"file": ("s.npy", data, "application/x-npy")}, "data": fields}


# (id, path, request keyword arguments (or a factory), expected status, expected problem kind)
CASES: list[tuple[str, str, Any, int, str]] = [
    # images
    ("bomb-png", "/v1/images/encode", lambda: image(bomb_png()), 413, "image-too-large"),
    ("text-named-png", "/v1/images/encode", image(b"hello, I am text\n" * 20), 415, "unsupported-media-type"),
    ("empty-file", "/v1/images/encode", image(b""), 415, "unsupported-media-type"),
    ("truncated-png", "/v1/images/encode", image(PNG[: len(PNG) // 2]), 415, "unsupported-media-type"),
    ("png-header-only", "/v1/images/encode", image(PNG[:40]), 415, "unsupported-media-type"),
    ("truncated-jpeg", "/v1/images/encode", image(JPEG[: len(JPEG) // 2], "in.jpg"), 415, "unsupported-media-type"),
    ("no-file", "/v1/images/encode", {"data": {"quality": "30"}}, 422, "validation-error"),
    ("keep-above-1", "/v1/images/encode", image(PNG, keep="1.5"), 422, "validation-error"),
    ("keep-negative", "/v1/images/encode", image(PNG, keep="-0.1"), 422, "validation-error"),
    ("keep-nan", "/v1/images/encode", image(PNG, keep="nan"), 422, "validation-error"),
    ("quality-inf", "/v1/images/encode", image(PNG, quality="inf"), 422, "validation-error"),
    ("bpp-zero", "/v1/images/encode", image(PNG, bpp="0"), 422, "validation-error"),
    ("level-text", "/v1/images/encode", image(PNG, level="deep"), 422, "validation-error"),
    ("two-targets", "/v1/images/encode", image(PNG, keep="0.5", quality="30"), 422, "invalid-parameter"),
    ("unknown-wavelet", "/v1/images/encode", image(PNG, wavelet="db4000"), 422, "invalid-parameter"),
    ("lossless-and-bpp", "/v1/images/encode", image(PNG, lossless="true", bpp="1"), 422, "invalid-parameter"),
    ("effort-unknown", "/v1/images/encode", image(PNG, lossless="true", effort="hard"), 422, "validation-error"),
    ("effort-max-lossy", "/v1/images/encode", image(PNG, effort="max"), 422, "invalid-parameter"),
    # curves
    ("curve-nan", "/v1/curves/encode", raw_json('{"points": [[0, 0], [NaN, 1], [2, 2]]}'), 422, "validation-error"),
    ("curve-infinity", "/v1/curves/encode", raw_json('{"points": [[0, 0], [Infinity, 1], [2, 2]]}'), 422, "validation-error"),
    ("curve-overflow", "/v1/curves/encode", raw_json('{"points": [[0, 0], [1e999, 1], [2, 2]]}'), 422, "validation-error"),
    ("curve-ragged", "/v1/curves/encode", {"json": {"points": [[0, 0], [1], [2, 2]]}}, 422, "invalid-parameter"),
    ("curve-flat-list", "/v1/curves/encode", {"json": {"points": [0, 1, 2, 3]}}, 422, "validation-error"),
    ("curve-4d", "/v1/curves/encode", {"json": {"points": [[0, 0, 0, 0]] * 12}}, 422, "invalid-parameter"),
    ("curve-empty", "/v1/curves/encode", {"json": {"points": []}}, 422, "validation-error"),
    ("curve-strings", "/v1/curves/encode", {"json": {"points": [["a", "b"]]}}, 422, "validation-error"),
    ("curve-keep-2", "/v1/curves/encode", {"json": {"points": [[0, 0]] * 9, "keep": 2}}, 422, "validation-error"),
    ("curve-extra-field", "/v1/curves/encode", {"json": {"points": [[0, 0]] * 9, "colour": 1}}, 422, "validation-error"),
    ("curve-not-json", "/v1/curves/encode", raw_json("{points: oops"), 422, "validation-error"),
    ("curve-closed-maybe", "/v1/curves/encode", {"json": {"points": [[0, 0]] * 9, "closed": "maybe"}}, 422, "validation-error"),
    ("transfer-ragged", "/v1/curves/transfer", {"json": {"source": [[0, 0], [1]], "base": [[0, 0], [1, 1]]}}, 422, "invalid-parameter"),
    # surfaces
    ("surface-ragged", "/v1/surfaces/encode", {"json": {"grid": [[0, 1, 2], [0, 1]]}}, 422, "invalid-parameter"),
    ("surface-1d", "/v1/surfaces/encode", {"json": {"grid": [0, 1, 2]}}, 422, "validation-error"),
    ("surface-nan", "/v1/surfaces/encode", raw_json('{"grid": [[0, NaN], [1, 2]]}'), 422, "validation-error"),
    ("surface-closed-3", "/v1/surfaces/encode", {"json": {"grid": [[0.0] * 8] * 8, "closed": [True, False, True]}}, 422, "validation-error"),
    ("surface-pickle-npy", "/v1/surfaces/encode", surface_npy(_npy(np.array([{"a": 1}] * 4, dtype=object))), 422, "invalid-parameter"),
    ("surface-truncated-npy", "/v1/surfaces/encode", surface_npy(_npy(np.zeros((16, 16)))[:-40]), 415, "unsupported-media-type"),
    ("surface-garbage-npy", "/v1/surfaces/encode", surface_npy(b"\x93NUMPY garbage"), 415, "unsupported-media-type"),
    ("surface-npy-nan", "/v1/surfaces/encode", surface_npy(_npy(np.full((8, 8), np.nan))), 422, "invalid-parameter"),
    ("surface-npy-1d", "/v1/surfaces/encode", surface_npy(_npy(np.zeros(30))), 422, "invalid-parameter"),
    ("surface-closed-bad", "/v1/surfaces/encode", surface_npy(_npy(np.zeros((8, 8))), closed="yes,no,maybe"), 422, "validation-error"),
    ("surface-closed-nested", "/v1/surfaces/encode", surface_npy(_npy(np.zeros((8, 8))), closed="[" * 5000), 422, "validation-error"),
    ("geojson-long-integer", "/v1/curves/encode", {"content": b'{"type": "LineString", "coordinates": [[1' + b"0" * 5000 + b', 0], [0, 1]]}', "headers": {"content-type": "application/geo+json"}}, 422, "invalid-parameter"),
    ("surface-text-plain", "/v1/surfaces/encode", {"content": b"1 2 3", "headers": {"content-type": "text/plain"}}, 415, "unsupported-media-type"),
    # bundles
    ("corrupt-bundle", "/v1/bundles/reconstruct", {"content": _flipped(IMAGE_BUNDLE, len(IMAGE_BUNDLE) // 2)}, 400, "invalid-bundle"),
    ("corrupt-bundle-inspect", "/v1/bundles/inspect", {"content": _flipped(IMAGE_BUNDLE, 20)}, 400, "invalid-bundle"),
    ("garbage-bundle", "/v1/bundles/reconstruct", {"content": b"PK\x03\x04 not ours"}, 400, "invalid-bundle"),
    ("empty-bundle", "/v1/bundles/inspect", {"content": b""}, 400, "invalid-bundle"),
    ("truncated-bundle", "/v1/bundles/reconstruct", {"content": IMAGE_BUNDLE[:30]}, 400, "invalid-bundle"),
    ("level-too-deep", "/v1/bundles/reconstruct", {"content": IMAGE_BUNDLE, "params": {"level": 40}}, 422, "invalid-parameter"),
    ("keep-negative-decode", "/v1/bundles/reconstruct", {"content": IMAGE_BUNDLE, "params": {"keep": -1}}, 422, "validation-error"),
    ("format-unknown", "/v1/bundles/reconstruct", {"content": IMAGE_BUNDLE, "params": {"format": "gif"}}, 422, "validation-error"),
    ("image-as-json", "/v1/bundles/reconstruct", {"content": IMAGE_BUNDLE, "params": {"format": "json"}}, 406, "not-acceptable"),
    ("curve-as-png", "/v1/bundles/reconstruct", {"content": CURVE_BUNDLE, "params": {"format": "png"}}, 406, "not-acceptable"),
    ("form-without-bundle", "/v1/bundles/reconstruct", {"files": {"other": ("b", b"x")}}, 422, "invalid-parameter"),
    ("form-keep-bad", "/v1/bundles/reconstruct", {"files": {"bundle": ("b", IMAGE_BUNDLE)}, "data": {"keep": "lots"}}, 422, "validation-error"),
]  # fmt: skip


def _check_problem(r: httpx.Response, status: int, kind: str) -> dict[str, Any]:
    assert r.status_code == status, r.text
    assert r.headers["content-type"] == "application/problem+json", r.headers
    body = r.json()
    assert body["type"] == f"urn:wavecore:problem:{kind}", body
    assert body["status"] == status
    assert body["title"] and body["detail"]
    return body


@pytest.mark.parametrize(
    ("path", "request_kwargs", "status", "kind"),
    [pytest.param(*case[1:], id=case[0]) for case in CASES],
)
async def test_bad_input_gets_a_problem(
    client: httpx.AsyncClient, path: str, request_kwargs: Any, status: int, kind: str
) -> None:
    kwargs = request_kwargs() if callable(request_kwargs) else request_kwargs
    r = await client.post(path, **kwargs)
    body = _check_problem(r, status, kind)
    if kind == "validation-error" and "not valid JSON" not in body["detail"]:
        assert body["errors"], body


async def test_unknown_path_and_method(client: httpx.AsyncClient) -> None:
    _check_problem(await client.get("/v1/nothing"), 404, "not-found")
    _check_problem(await client.get("/v1/images/encode"), 405, "method-not-allowed")


async def test_validation_errors_name_the_field(client: httpx.AsyncClient) -> None:
    r = await client.post("/v1/images/encode", **image(PNG, keep="1.5"))
    body = _check_problem(r, 422, "validation-error")
    assert body["errors"][0]["loc"][-1] == "keep"
    assert "keep" in body["detail"]


@pytest.mark.parametrize(
    ("path", "request_kwargs", "name"),
    [
        ("/v1/images/encode", image(PNG), "bpp"),
        ("/v1/grids/encode", surface_npy(_npy(np.zeros((8, 8)))), "max_error"),
        ("/v1/surfaces/encode", {"json": {"grid": [[0.0] * 8] * 8}}, "keep"),
        ("/v1/curves/encode", {"json": {"points": [[0, 0], [1, 1], [2, 0]] * 3}}, "tolerence"),
        ("/v1/bundles/reconstruct", {"content": IMAGE_BUNDLE}, "levle"),
    ],
    ids=["image-form-route", "grid-form-route", "surface-body-route", "curve-typo", "bundle-typo"],
)
async def test_unknown_query_parameters_are_refused_not_ignored(
    client: httpx.AsyncClient, path: str, request_kwargs: dict[str, Any], name: str
) -> None:
    # A target in the query string of a route that reads it elsewhere would otherwise be
    # dropped silently, and the caller would get a bundle coded to the default.
    r = await client.post(path, params={name: "1"}, **request_kwargs)
    body = _check_problem(r, 400, "bad-request")
    assert repr(name) in body["detail"]


async def test_declared_query_parameters_still_pass(client: httpx.AsyncClient) -> None:
    r = await client.post("/v1/bundles/reconstruct", params={"level": 1}, content=IMAGE_BUNDLE)
    assert r.status_code == 200, r.text


async def test_bomb_refused_by_the_header_before_decoding(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    # A limit below the bomb's size but above half of it, where Pillow only warns: our check
    # of the header's size stops it before any pixel is decoded.
    async with make_client(max_pixels=5_000_000) as c:
        body = _check_problem(
            await c.post("/v1/images/encode", **image(bomb_png(3000, 3000))), 413, "image-too-large"
        )
        assert "3000 × 3000" in body["detail"] and "5000000" in body["detail"]
        small = await c.post("/v1/images/encode", **image(PNG))
        assert small.status_code == 200


async def test_body_limit_by_length_and_while_streaming(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    async with make_client(max_upload_bytes=4096) as c:
        big = image(bytes(10_000))
        _check_problem(await c.post("/v1/images/encode", **big), 413, "body-too-large")

        async def chunks() -> Any:  # no Content-Length: counted while the body streams in
            for _ in range(10):
                yield bytes(1000)

        r = await c.post("/v1/bundles/inspect", content=chunks())
        _check_problem(r, 413, "body-too-large")
        r = await c.post(
            "/v1/curves/encode", content=chunks(), headers={"content-type": "application/json"}
        )
        _check_problem(r, 413, "body-too-large")
        form = c.build_request("POST", "/", files={"file": ("a.png", bytes(20_000))})
        body = form.read()

        async def form_chunks() -> Any:  # a streamed multipart upload
            for i in range(0, len(body), 1000):
                yield body[i : i + 1000]

        headers = {"content-type": form.headers["content-type"]}
        r = await c.post("/v1/images/encode", content=form_chunks(), headers=headers)
        _check_problem(r, 413, "body-too-large")
        # under the limit: read and answered (a truncated bundle still inspects: prefixes work)
        r = await c.post("/v1/bundles/inspect", content=IMAGE_BUNDLE[:3000])
        assert r.status_code == 200 and r.json()["kind"] == "image"


async def test_bundles_that_decode_beyond_the_limits_are_refused_before_decoding(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    """A small bundle can declare a huge result: the limits of uploads apply to it too."""
    surface = wavecore.encode_surface(np.zeros((12, 10, 3)), quality=40)
    async with make_client(max_pixels=2000, max_points=29, max_grid_points=119) as c:
        r = await c.post("/v1/bundles/reconstruct", content=IMAGE_BUNDLE)
        detail = _check_problem(r, 413, "bundle-too-large")["detail"]
        assert "52 × 40 image" in detail and "2000 pixels" in detail
        r = await c.post("/v1/bundles/reconstruct", content=CURVE_BUNDLE, params={"level": 1})
        assert "30 points" in _check_problem(r, 413, "bundle-too-large")["detail"]
        r = await c.post("/v1/bundles/reconstruct", content=surface)
        assert "12 × 10 surface" in _check_problem(r, 413, "bundle-too-large")["detail"]
        # Describing a bundle decodes nothing: still allowed.
        assert (await c.post("/v1/bundles/inspect", content=IMAGE_BUNDLE)).status_code == 200
    async with make_client(max_dimension=2) as c:
        r = await c.post("/v1/bundles/reconstruct", content=surface)
        assert "3-D points" in _check_problem(r, 413, "bundle-too-large")["detail"]
        assert (await c.post("/v1/bundles/reconstruct", content=CURVE_BUNDLE)).status_code == 200


async def test_a_bundle_of_a_legacy_coder_counts_its_planes(
    make_client: Callable[..., httpx.AsyncClient], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Context coder versions 2 and 3 still decode, plane by plane in Python, and a volume is
    a plane per slice and band: such a bundle's planes count as samples of its cost."""
    import wavecore.codec.plan as plan

    volume = np.random.default_rng(3).standard_normal((40, 1, 1))
    modern = wavecore.encode_grid(volume, wavelet="cdf97", rmse=0.1)
    with monkeypatch.context() as patch:
        patch.setattr(plan.Plan, "context_version", property(lambda self: 3))
        legacy = wavecore.encode_grid(volume, wavelet="cdf97", rmse=0.1)
    assert wavecore.inspect(legacy)["header"]["cparams"]["version"] == 3
    np.testing.assert_array_equal(wavecore.decode(legacy), wavecore.decode(modern))
    async with make_client(max_pixels=2000) as c:  # 10 000 samples a request
        r = await c.post("/v1/bundles/reconstruct", content=legacy)
        detail = _check_problem(r, 413, "too-costly")["detail"]
        assert "8 × 8 × 40 samples in 160 planes of context coder version 3" in detail
        r = await c.post("/v1/bundles/reconstruct", content=modern, params={"format": "npy"})
        assert r.status_code == 200, r.text
        assert np.load(io.BytesIO(r.content)).shape == volume.shape


async def test_point_and_grid_limits(make_client: Callable[..., httpx.AsyncClient]) -> None:
    async with make_client(max_points=50, max_grid_points=100) as c:
        r = await c.post("/v1/curves/encode", json={"points": [[0.0, 1.0]] * 51})
        assert "51 points" in _check_problem(r, 422, "invalid-parameter")["detail"]
        assert (
            await c.post("/v1/curves/encode", json={"points": [[0.0, 1.0]] * 50})
        ).status_code == 200
        r = await c.post("/v1/surfaces/encode", json={"grid": [[0.0] * 11] * 10})
        _check_problem(r, 422, "invalid-parameter")
        r = await c.post("/v1/surfaces/encode", **surface_npy(_npy(np.zeros((11, 10)))))
        _check_problem(r, 422, "invalid-parameter")


async def test_overload_gets_a_quick_503_with_retry_after(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    async with make_client(threads=1, queue_size=0) as c:
        pool = c._transport.app.state.pool  # type: ignore[attr-defined]
        held = pool.admit()  # every slot taken
        r = await c.post("/v1/images/encode", **image(PNG))
        body = _check_problem(r, 503, "overloaded")
        assert r.headers["retry-after"].isdigit() and "slots" in body["detail"]
        assert (await c.get("/healthz")).status_code == 200  # health needs no slot
        held.release()
        assert (await c.post("/v1/images/encode", **image(PNG))).status_code == 200
        metrics = (await c.get("/metrics")).text
        assert 'wavecore_http_errors_total{kind="overloaded"} 1.0' in metrics


async def test_timeout_gets_a_503(make_client: Callable[..., httpx.AsyncClient]) -> None:
    async with make_client(request_timeout=1e-4) as c:
        r = await c.post("/v1/images/encode", **image(image_file(test_image((256, 256)))))
        _check_problem(r, 503, "timeout")
        assert "retry-after" in r.headers
        # the abandoned job still holds its slot until its thread is free, then gives it back
        pool = c._transport.app.state.pool  # type: ignore[attr-defined]
        for _ in range(200):
            if pool.in_use == 0:
                break
            await asyncio.sleep(0.05)
        assert pool.in_use == 0


async def test_made_up_methods_share_one_metrics_label(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    async with make_client() as c:
        for i in range(50):
            r = await c.request(f"BREW{i}", "/healthz")
            assert r.status_code == 405
        metrics = (await c.get("/metrics")).text
        assert "BREW" not in metrics
        assert 'method="other"' in metrics


async def test_memory_error_is_a_503_problem(
    make_client: Callable[..., httpx.AsyncClient], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Jobs run in worker processes (a MemoryError there is the pool's 413 'out-of-memory',
    # tested in test_service_work.py); this is the server process's own handler.
    async def out_of_memory(*args: Any, **kwargs: Any) -> bytes:
        raise MemoryError

    monkeypatch.setattr(curves_route, "run_work", out_of_memory)
    async with make_client() as c:
        r = await c.post("/v1/curves/encode", json={"points": [[0.0, 1.0]] * 20})
        body = _check_problem(r, 503, "insufficient-memory")
        assert "memory" in body["detail"] and r.headers["retry-after"].isdigit()


def test_problems_survive_pickling() -> None:
    """Jobs may run in worker processes: a problem must come back whole."""
    import pickle

    from service.errors import Problem

    problem = Problem("too-costly", "too much", headers={"X": "1"}, errors=[{"loc": ["a"]}])
    back = pickle.loads(pickle.dumps(problem))
    assert (back.kind, back.status, back.detail, back.headers, back.errors) == (
        "too-costly",
        413,
        "too much",
        {"X": "1"},
        [{"loc": ["a"]}],
    )


async def test_cost_check_names_the_figure_and_the_limit(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    # max_pixels 2000 → 10 000 samples per request.  A 1 × 2000 image passes the pixel limit
    # but is padded to 8 rows for one level: 16 000 samples.
    async with make_client(max_pixels=2000) as c:
        thin = image(image_file(np.zeros((1, 2000), np.uint8)))
        detail = _check_problem(await c.post("/v1/images/encode", **thin), 413, "too-costly")[
            "detail"
        ]
        assert "2000 × 1 image" in detail and "16000 samples" in detail and "10000" in detail
        lossless = image(image_file(np.zeros((1, 2000), np.uint8)), lossless="true")
        assert (await c.post("/v1/images/encode", **lossless)).status_code == 200  # unpadded
        square = image(image_file(test_image((40, 50))))
        assert (await c.post("/v1/images/encode", **square)).status_code == 200
        # A bundle is judged by what its header declares: its padded size, 8 × 1990.
        thin_bundle = wavecore.encode_image(test_image((1, 1990)), quality=35)
        r = await c.post("/v1/bundles/reconstruct", content=thin_bundle)
        assert "8 × 1990 samples" in _check_problem(r, 413, "too-costly")["detail"]


async def test_transfer_level_is_bounded_by_the_source(client: httpx.AsyncClient) -> None:
    source = np.cumsum(np.random.default_rng(4).normal(size=(40, 2)), axis=0).tolist()
    body = {"source": source, "base": [[0, 0], [1, 1]], "level": 30}
    r = await client.post("/v1/curves/transfer", json=body)
    problem = _check_problem(r, 422, "invalid-parameter")
    assert "level 30" in problem["detail"] and problem["errors"][0]["loc"] == ["body", "level"]
    assert "from 1 to" in problem["detail"]  # a transfer needs a level: 0 is refused
    # the deepest level the message offers is accepted
    deepest = int(problem["detail"].rsplit(" ", 1)[-1])
    r = await client.post("/v1/curves/transfer", json={**body, "level": deepest})
    assert r.status_code == 200 and r.json()["shape"] == [40, 2]


async def test_a_closed_transfer_to_one_coarse_point_offers_the_levels_that_fit(
    client: httpx.AsyncClient,
) -> None:
    t = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    source = np.stack([np.cos(t), np.sin(t)], axis=1).tolist()
    body = {"source": source, "base": [[0, 0], [1, 0], [1, 1]], "closed": True, "level": 4}
    r = await client.post("/v1/curves/transfer", json=body)
    problem = _check_problem(r, 422, "invalid-parameter")
    assert "1 point" in problem["detail"] and problem["detail"].endswith("from 1 to 3")
    r = await client.post("/v1/curves/transfer", json={**body, "level": 3})
    assert r.status_code == 200 and r.json()["shape"] == [16, 2]


@pytest.mark.parametrize("level", [31, 1000])
async def test_a_surface_level_past_30_is_named_as_sent(
    client: httpx.AsyncClient, level: int
) -> None:
    body = {"grid": [[0.0] * 8] * 8, "level": level}
    r = await client.post("/v1/surfaces/encode", json=body)
    problem = _check_problem(r, 422, "invalid-parameter")
    assert f"level {level} is more than 30" in problem["detail"]  # not the clamped 30
