"""Golden bundles: committed bytes that every future version must still decode the same way.

``tests/golden/make_golden.py`` made them; see its docstring before regenerating anything.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

import wavecore
from wavecore.blockcoder import block_table
from wavecore.bundle import read_bundle
from wavecore.entropy import CONTEXT_VERSIONS

GOLDEN = Path(__file__).resolve().parent / "golden"
MANIFEST = json.loads((GOLDEN / "MANIFEST.json").read_text())


def test_the_golden_set_is_complete() -> None:
    kinds = {entry["kind"] for entry in MANIFEST.values()}
    assert kinds == {"image", "curve", "surface"}
    assert any(entry["lossless"] for entry in MANIFEST.values())
    # Every format version a reader must still read has bundles here (2.0: the binary header;
    # 3.1: images with derived weights; 5.0: the curve layout; 6.0: curves with block checks
    # in chunks of several blocks; 7.0: pictures enlarged by pixel replication).
    versions = {entry["version"] for entry in MANIFEST.values()}
    assert versions >= {"1.0", "1.1", "1.2", "2.0", "3.0", "3.1", "4.0", "5.0", "6.0", "7.0"}
    assert sorted(p.stem for p in GOLDEN.glob("*.wvb")) == sorted(MANIFEST)
    # Every context coder version that decoders must still read has bundles here.
    coders = {entry["cparams"].get("version") for entry in MANIFEST.values()}
    assert coders >= set(CONTEXT_VERSIONS)


@pytest.mark.parametrize("name", sorted(MANIFEST))
def test_golden_bundle_decodes_as_committed(name: str) -> None:
    entry = MANIFEST[name]
    bundle = (GOLDEN / f"{name}.wvb").read_bytes()
    assert hashlib.sha256(bundle).hexdigest() == entry["sha256"], "the golden file was changed"
    expected = np.load(GOLDEN / f"{name}.npy", allow_pickle=False)
    decoded = wavecore.decode(bundle)
    assert decoded.dtype == expected.dtype and decoded.shape == expected.shape
    if entry["lossless"]:
        assert np.array_equal(decoded, expected)
    elif decoded.dtype.kind == "u":
        # Float rounding may differ in the last bit between machines and BLAS builds, which can
        # move a value across a rounding boundary; nothing more.
        difference = np.abs(decoded.astype(np.int64) - expected)
        assert difference.max() <= 1 and np.count_nonzero(difference) <= max(
            1, decoded.size // 1000
        )
    else:
        np.testing.assert_allclose(decoded, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    info = wavecore.inspect(bundle)
    assert info["version"] == entry["version"]
    for k in range(info["levels"] + 1):
        assert wavecore.decode(bundle, level=k).dtype == expected.dtype


def test_the_6_0_golden_has_chunks_that_check_their_blocks() -> None:
    # The point of 6.0: this golden's two chunks have two code-blocks each, stored with their
    # block checks (so the golden covers that path of the reader), and a damaged block of the
    # coarse chunk is found by name and, with damaged="zero", loses only itself.
    bundle = (GOLDEN / "v6_0_curve_series_two_blocks.wvb").read_bytes()
    parsed = read_bundle(bundle)
    assert parsed.version == (6, 0) and parsed.checked == ((2, 0), (2, 1))
    _, lengths = block_table(bytes(parsed.chunks[0]), 2)
    assert lengths[1] > 0
    block_1_end = len(bundle) - len(parsed.chunks[1])  # chunk 0 ends with its block 1
    clean = wavecore.decode(bundle)
    damaged = bytearray(bundle)
    damaged[block_1_end - int(lengths[1]) // 2] ^= 0x5A
    with pytest.raises(wavecore.BundleError, match=r"chunk 0 is corrupt: code-block\(s\) \[1\]"):
        wavecore.decode(bytes(damaged))
    out = wavecore.decode(bytes(damaged), damaged="zero")
    differs = np.flatnonzero(out != clean)
    # Block 1 holds the coarse values from 16 384 on, which reach the points from about
    # 2 × 16 384 on (a few points' margin for the synthesis).
    assert differs.size and differs.min() >= 2 * 16_384 - 8
