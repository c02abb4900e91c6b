"""What the image encoder chooses per picture: the wavelet of ``wavelet="auto"`` (the
default), and the colour transform of a lossy colour picture.

**The wavelet.**

CDF 9/7 wins the measured rate–distortion on photographs by 13–90 % (BD-rate against Haar on
scikit-image's pictures).  Haar wins by 45–70 % where most 2 × 2 blocks of pixels are flat:
pictures enlarged by pixel replication (scikit-image's ``moon`` is a 256² picture at 512²),
binary and two-tone graphics (``horse``, ``binary_blobs``, ``checkerboard``).  An *exact*
enlargement is now coded as its source (:mod:`wavecore.codec.replication`), and this choice
is then made on the source; it still serves the graphics and near-enlargements.  Its finest
details there are exactly zero, while CDF 9/7's long filters spread every edge over several
coefficients.  Between those, at a flat share of 0.17–0.42 (``page``, ``logo``, ``retina``),
CDF 9/7 wins or ties, so the threshold sits in the gap.

The share is counted on a sample of the rows (a thirty-second of a large picture's) and, unless
the sample is clearly a photograph's, again over every row.  A 2048² RGB photograph's choice
takes about a millisecond.

**The colour transform** of a lossy colour picture: YCbCr, or the picture's own rotation of
the colour space where it costs less (:func:`choose_colour`).
"""

from __future__ import annotations

import numpy as np

from ..colour import YCBCR_MATRIX, klt_matrix, klt_name

__all__ = [
    "AUTO",
    "AUTO_CANDIDATES",
    "FLAT_SHARE_FOR_HAAR",
    "choose_colour",
    "choose_image_wavelet",
    "colour_cost",
    "colour_details",
    "flat_block_share",
]

#: The wavelet name that asks for the per-picture choice.
AUTO = "auto"
#: The wavelets it chooses from.
AUTO_CANDIDATES = ("cdf97", "haar")
#: Haar is chosen at or above this share of flat 2 × 2 blocks (measured: Haar wins at 0.81
#: and above, CDF 9/7 at 0.42 and below).
FLAT_SHARE_FOR_HAAR = 0.7
#: The sample takes every this-many-th pair of rows (fewer on a short picture: at least
#: :data:`_SAMPLE_PAIRS` pairs), a thirty-second of a large picture's rows.
_SAMPLE_STEP = 32
_SAMPLE_PAIRS = 16
#: A sample this far below the threshold decides (cdf97) without the full count; Haar is
#: only chosen on the full count.
_SAMPLE_MARGIN = 0.2
#: Row pairs compared at once (bounds the temporaries of a large picture).
_PAIRS_PER_SLICE = 256


def flat_block_share(image: np.ndarray, row_step: int = 1) -> float:
    """The share of the picture's 2 × 2 blocks (even rows and columns, every channel) whose
    four pixels are equal, over every ``row_step``-th pair of rows.

    Examples
    --------
    >>> import numpy as np
    >>> flat_block_share(np.kron(np.arange(12).reshape(3, 4), np.ones((2, 2))))
    1.0
    >>> flat_block_share(np.arange(16.0).reshape(4, 4))
    0.0
    """
    pairs, cols = image.shape[0] // 2, image.shape[1] // 2 * 2
    if pairs == 0 or cols == 0:
        return 0.0
    chosen = range(0, pairs, row_step)
    flat = 0
    for start in range(0, len(chosen), _PAIRS_PER_SLICE):
        rows = 2 * np.asarray(chosen[start : start + _PAIRS_PER_SLICE])
        top, bottom = image[rows, :cols], image[rows + 1, :cols]
        corner = top[:, 0::2]
        same = (corner == top[:, 1::2]) & (corner == bottom[:, 0::2]) & (corner == bottom[:, 1::2])
        if same.ndim == 3:  # every channel
            same = same.all(axis=2)
        flat += int(np.count_nonzero(same))
    return flat / (len(chosen) * (cols // 2))


def choose_image_wavelet(image: np.ndarray) -> str:
    """``"haar"`` for a picture of mostly flat 2 × 2 blocks (:data:`FLAT_SHARE_FOR_HAAR`),
    ``"cdf97"`` for any other (see the module text for the measurements).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> photo = rng.integers(0, 256, (64, 64))
    >>> choose_image_wavelet(photo), choose_image_wavelet(np.kron(photo, np.ones((2, 2))))
    ('cdf97', 'haar')
    """
    step = max(1, min(_SAMPLE_STEP, image.shape[0] // 2 // _SAMPLE_PAIRS))
    if flat_block_share(image, step) < FLAT_SHARE_FOR_HAAR - _SAMPLE_MARGIN:
        return "cdf97"
    return "haar" if flat_block_share(image) >= FLAT_SHARE_FOR_HAAR else "cdf97"


#: The colour choice samples the differences at this many rows and columns at most (evenly
#: spaced: 32 × 256 places, down and across, whatever the picture's size).
_COLOUR_SAMPLE_ROWS = 32
_COLOUR_SAMPLE_COLUMNS = 256
#: The per-picture matrix must beat YCbCr's cost (:func:`colour_cost`) by this much.
_COLOUR_MARGIN = 0.01


def colour_details(image: np.ndarray) -> np.ndarray:
    """``(n, 3)`` differences of neighbouring pixels (down and across) at evenly spaced places:
    the details that a wavelet codes, where a picture's smooth shading does not weigh in."""
    rows = np.unique(np.linspace(0, image.shape[0] - 2, _COLOUR_SAMPLE_ROWS).astype(np.intp))
    cols = np.unique(np.linspace(0, image.shape[1] - 2, _COLOUR_SAMPLE_COLUMNS).astype(np.intp))
    here = image[np.ix_(rows, cols)][..., :3].astype(np.float64)
    down = image[np.ix_(rows + 1, cols)][..., :3] - here
    across = image[np.ix_(rows, cols + 1)][..., :3] - here
    return np.concatenate([down.reshape(-1, 3), across.reshape(-1, 3)])


def _mixed(details: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """``details @ matrix.T``, a column at a time (NumPy's matmul of an ``(n, 3)`` array by a
    3 × 3 one takes a slow path)."""
    return np.stack([details @ row for row in matrix], axis=1)


def colour_cost(details: np.ndarray, matrix: np.ndarray) -> float:
    """What coding ``details`` after ``matrix`` costs, up to a constant: the sum over the
    channels of the log of their mean magnitude, each in units of the error it makes in RGB
    (the column norms of the inverse).  A Laplacian's rate at a given distortion goes with
    that log; the mean magnitude, unlike the variance, is not ruled by the few largest edges.
    """
    spread = np.abs(_mixed(details, matrix)).mean(axis=0)
    gains = np.sqrt((np.linalg.inv(matrix) ** 2).sum(axis=0))
    floor = 1e-9 * float(np.abs(details).mean()) + 1e-300  # flat channels tie, not -inf
    return float(np.log(spread * gains + floor).sum())


def choose_colour(image: np.ndarray) -> str:
    """``"ycbcr"``, or a per-picture matrix (``"klt:..."``, :func:`wavecore.colour.klt_name`)
    where it codes the picture's colour details in fewer bits (:func:`colour_cost`).

    The matrix is the Karhunen–Loève transform of the details (the eigenvectors of their
    covariance, strongest first, each signed so that its largest entry is positive, the last
    flipped if need be to make it a rotation, which three angles name): the orthogonal
    transform that decorrelates them.  YCbCr's fixed matrix is made for average photographs; a
    picture's own colours are often far from them.  Measured against YCbCr (BD-rate over
    0.25–2 bpp, cdf97, RGB PSNR, whole bundles): astronaut −3.6 %, coffee −9.1 %, chelsea
    −6.1 %, rocket −18.2 %, logo −12.4 %, hubble_deep_field −13.8 %, immunohistochemistry
    −5.4 %; the cost keeps YCbCr on retina, where the matrix lost 3.2 %.  (The transform of
    the pixels' own covariance, ruled by smooth shading, lost 19 % there and 5 % on
    immunohistochemistry.)

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> grey = rng.integers(0, 256, (32, 32, 1)).repeat(3, axis=2)
    >>> choose_colour(grey)
    'ycbcr'
    >>> tinted = np.concatenate([grey[..., :1], grey[..., :1] // 2, 255 - grey[..., :1]], axis=2)
    >>> choose_colour(tinted).startswith("klt:")
    True
    """
    if image.ndim != 3 or image.shape[2] < 3 or min(image.shape[:2]) < 2:
        return "ycbcr"
    with np.errstate(all="ignore"):
        details = colour_details(image)
        covariance = details.T @ details
        if not np.all(np.isfinite(covariance)):
            return "ycbcr"
        _, vectors = np.linalg.eigh(covariance)
        matrix = vectors[:, ::-1].T.copy()
        for row in matrix:
            if row[np.argmax(np.abs(row))] < 0:
                row *= -1
        if np.linalg.det(matrix) < 0:  # a rotation, which three angles name
            matrix[2] *= -1
        try:
            name = klt_name(matrix)
            quantized = klt_matrix(name)
        except ValueError:
            return "ycbcr"
        ours, standard = colour_cost(details, quantized), colour_cost(details, YCBCR_MATRIX)
    return name if ours < standard - _COLOUR_MARGIN else "ycbcr"
