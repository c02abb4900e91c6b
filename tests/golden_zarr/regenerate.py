"""Write the golden chunks of tests/test_zarr.py (run once per chunk-format change, by hand).

``python tests/golden_zarr/regenerate.py`` codes each case's source (tests/test_zarr.py's
``smooth_field``) and records the file, the settings and the decoded values' SHA-256.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))

from zarr_fields import smooth_field  # noqa: E402

from wavecore.zarr import decode_chunk, encode_chunk  # noqa: E402

CASES = [
    # Coded when cdf97 was the default wavelet of max_error chunks (the wavelet core + outliers).
    {"file": "field_f4_max_error.wzc", "shape": [48, 40], "seed": 21, "dtype": "float32",
     "config": {"max_error": 0.05, "wavelet": "cdf97"}},
    {"file": "edge_f8_max_error.wzc", "shape": [7, 33], "seed": 22, "dtype": "float64",
     "config": {"max_error": 0.01, "wavelet": "cdf97"}},
    {"file": "volume_f4_max_error.wzc", "shape": [3, 20, 24], "seed": 23, "dtype": "float32",
     "config": {"max_error": 0.1, "wavelet": "cdf97"}},
    {"file": "grid_i2_lossless.wzc", "shape": [40, 40], "seed": 24, "dtype": "int16",
     "config": {"lossless": True}},
    # No wavelet named: encode_grid's interpolation coder (grid container version 2).
    {"file": "field_f4_interpolation.wzc", "shape": [48, 40], "seed": 25, "dtype": "float32",
     "config": {"max_error": 0.05}},
    {"file": "image_u1_interpolation.wzc", "shape": [1, 37, 52], "seed": 26, "dtype": "uint8",
     "config": {"max_error": 3}},
]  # fmt: skip


def main() -> None:
    """Write the chunks not yet written; ``--all`` rewrites every one (a format change)."""
    for case in CASES:
        path = HERE / case["file"]
        if not path.exists() or "--all" in sys.argv:
            source = smooth_field(tuple(case["shape"]), seed=case["seed"], dtype=case["dtype"])
            path.write_bytes(encode_chunk(source, case["config"]))
        case["sha256"] = hashlib.sha256(decode_chunk(path.read_bytes()).tobytes()).hexdigest()
    (HERE / "cases.json").write_text(json.dumps({"cases": CASES}, indent=1) + "\n")


if __name__ == "__main__":
    main()
