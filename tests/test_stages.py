"""The stage registry (wavecore.codec.stages): one suite run against every registered stage."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from wavecore.codec import stages
from wavecore.errors import BundleError

CONFIGS: list[tuple[str, dict[str, Any]]] = [
    ("transform", {"id": "wavelet", "wavelet": "bspline2", "boundary": ["open", "open"]}),
    ("transform", {"id": "wavelet", "wavelet": "cdf97", "boundary": ["closed"]}),
    ("transform", {"id": "reversible", "lifting": ["legall53", "haar"]}),
    ("quantizer", {"id": "none"}),
    (
        "quantizer",
        {"id": "deadzone", "name": "deadzone", "step": 2.0, "weights": [[1.0]], "rounding": 0.3},
    ),
    ("coder", {"id": "context", "coder": "context"}),
    ("coder", {"id": "zlib", "coder": "zlib"}),
    ("colour", {"id": "none"}),
    ("colour", {"id": "ycbcr"}),
    ("colour", {"id": "rct"}),
    *[("colour", {"id": f"rct-p{weight}"}) for weight in range(-8, 9) if weight],
]


class _Geometry:
    kind = "image"
    levels = 2
    axes = (0, 1)
    pads = ((0, 0), (0, 0))


@pytest.mark.parametrize(("kind", "config"), CONFIGS)
def test_config_round_trip(kind: str, config: dict[str, Any]) -> None:
    stage = stages.get_stage(kind, config)
    assert stage.codec_id == config["id"]
    again = stages.get_stage(kind, stage.get_config())
    assert again.get_config() == stage.get_config()
    assert type(again) is type(stage)


def test_every_registered_stage_is_covered() -> None:
    assert stages.registered_stages() == sorted({(k, config["id"]) for k, config in CONFIGS})


@pytest.mark.parametrize("kind", ["transform", "quantizer", "coder", "colour"])
def test_unknown_ids_are_a_bundle_error(kind: str) -> None:
    with pytest.raises(BundleError, match=f"unknown {kind} stage"):
        stages.get_stage(kind, {"id": "no-such-stage"})
    with pytest.raises(BundleError):
        stages.get_stage(kind, {"no": "id"})


@pytest.mark.parametrize("config", [c for k, c in CONFIGS if k == "transform"])
def test_transforms_invert_and_know_their_shapes(config: dict[str, Any]) -> None:
    transform = stages.get_transform(config)
    axes = (0,) if len(config.get("boundary", [0, 0])) == 1 else (0, 1)
    geometry = _Geometry()
    geometry.axes = axes
    size = (34, 26, 3) if axes == (0, 1) else (40, 2)
    rng = np.random.default_rng(21)
    data = rng.integers(0, 256, size) if transform.lossless else rng.random(size)
    coeffs = transform.forward(data, 2)
    shapes = transform.band_shapes(size, 2, axes)
    assert [
        np.shape(e) if not isinstance(e, tuple) else tuple(b.shape for b in e) for e in coeffs
    ] == shapes
    back = transform.inverse(coeffs, geometry)
    if transform.lossless:
        assert np.array_equal(back, data)
    else:
        assert np.allclose(back, data, atol=1e-9)


@pytest.mark.parametrize("config", [c for k, c in CONFIGS if k == "coder"])
def test_coders_round_trip(config: dict[str, Any]) -> None:
    coder = stages.get_coder(config)
    rng = np.random.default_rng(22)
    q = [
        rng.integers(-9, 9, (5, 4)).astype(np.int32),
        tuple(rng.integers(-3, 3, (5, 4)).astype(np.int32) for _ in range(3)),
    ]
    chunks, params = coder.encode(q)
    back = stages.get_coder({**params, "id": params["coder"]}).decode(
        chunks, [(5, 4), ((5, 4),) * 3]
    )
    assert np.array_equal(back[0], q[0])
    assert all(np.array_equal(a, b) for a, b in zip(back[1], q[1], strict=True))


@pytest.mark.parametrize("config", [c for k, c in CONFIGS if k == "colour"])
def test_colours_invert(config: dict[str, Any]) -> None:
    colour = stages.get_colour(config)
    rgb = np.random.default_rng(23).integers(0, 256, (6, 5, 3))
    back = colour.inverse(colour.forward(rgb))
    assert np.allclose(back, rgb, atol=1e-9)


def test_the_header_maps_to_one_pipeline() -> None:
    header = {
        "wavelet": "reversible",
        "boundary": ["symmetric", "symmetric"],
        "lifting": ["haar"],
        "colour": "rct",
        "quantizer": "none",
        "qparams": {},
        "coder": "context",
        "cparams": {"coder": "context"},
    }
    pipe = stages.pipeline(header)
    assert [s.codec_id for s in pipe] == ["rct", "reversible", "none", "context"]
    assert pipe.transform.lossless
    lossy = {**header, "wavelet": "haar", "colour": "ycbcr", "quantizer": "deadzone"}
    lossy["qparams"] = {"name": "deadzone", "step": 1.0, "weights": [[1.0]], "rounding": 0.3}
    assert [s.codec_id for s in stages.pipeline(lossy)] == [
        "ycbcr",
        "wavelet",
        "deadzone",
        "context",
    ]
