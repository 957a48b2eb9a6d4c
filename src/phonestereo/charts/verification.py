"""The verification chart: a chessboard with four circle pairs (thesis §1.2.2, §2.2).

The detector finds the four circle pairs first (connected components, the area–circumference
relation of a circle, similar radii within a pair), then the chessboard corners; the circles
anchor the (row, col) labels, so wide↔tele matching is inherent and a partly visible chart
(the tele sees about a third of the wide's field) still gives correctly labelled corners.

Board layout (both classes): square (row, col) spans
u ∈ [margin + col·s, margin + (col + 1)·s], v likewise with row; square (0, 0) (top left) is
black and colours alternate. Inner corner (i, j) is the corner shared by squares (i, j) and
(i + 1, j + 1), at (u, v) = margin + ((j + 1)·s, (i + 1)·s); an n × m-square board has
(n − 1) × (m − 1) of them, listed row by row (row i, then column j), like OpenCV's object points.

Circle pairs: each circle (radius 0.3 square) is centred in a square, so the corners stay
untouched (circle edge ≥ 0.41 square from every corner). A chessboard's edge-adjacent squares
always differ in colour, so the two circles of a pair sit in the nearest *same-coloured*
squares along the pair's axis, two squares apart. The four pairs differ by axis (``"h"``:
same row, ``"v"``: same column) and polarity (``"dark"``: black circles in white squares,
``"light"``: white circles in black squares), so each pair is identifiable on its own. All
eight circles lie within the central 8 × 6 squares (the tele's view at 0.8 m), at least three
squares from any circle of another pair.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from phonestereo.charts.base import (
    INK_BLACK,
    PAPER_WHITE,
    Array,
    IntArray,
    Keypoints,
    blockwise,
    check_uv,
    require_reflectance,
)
from phonestereo.errors import InputError

#: Circle radius as a fraction of the square side.
CIRCLE_RADIUS_SQUARES = 0.3

#: The four pairs: name, axis, polarity, and the two squares as (row, col) offsets from the
#: board's centre square (rows // 2, cols // 2) (shifted one column left if that is white).
_PAIR_LAYOUT: tuple[tuple[str, Literal["h", "v"], Literal["dark", "light"], tuple[int, ...]], ...]
_PAIR_LAYOUT = (
    ("h_dark", "h", "dark", (-3, -4, -3, -2)),
    ("v_light", "v", "light", (-3, 3, -1, 3)),
    ("v_dark", "v", "dark", (0, -3, 2, -3)),
    ("h_light", "h", "light", (2, 0, 2, 2)),
)


@dataclass(frozen=True, eq=False)
class CirclePair:
    """Two equal circles that anchor the chessboard labels."""

    #: ``"h_dark"``, ``"v_light"``, ``"v_dark"`` or ``"h_light"``.
    name: str
    #: ndarray, shape (2, 2). Circle centres (u, v), metres; the first is the top/left one.
    centers_uv: Array
    #: Circle radius, metres.
    radius_m: float
    #: ``"dark"``: black circles in white squares; ``"light"``: white circles in black squares.
    polarity: Literal["dark", "light"]
    #: ``"h"``: the circles share a row (two columns apart); ``"v"``: they share a column.
    axis: Literal["h", "v"]
    #: ndarray of int, shape (2, 2). (row, col) of the square that holds each circle.
    square_ids: IntArray = field(default_factory=lambda: np.zeros((2, 2), dtype=np.int64))

    def __post_init__(self) -> None:
        c = np.array(self.centers_uv, dtype=np.float64, copy=True).reshape(2, 2)
        s = np.array(self.square_ids, dtype=np.int64, copy=True).reshape(2, 2)
        c.setflags(write=False)
        s.setflags(write=False)
        object.__setattr__(self, "centers_uv", c)
        object.__setattr__(self, "square_ids", s)


def _check_board(
    board: Chessboard | VerificationChart, squares: tuple[int, int]
) -> tuple[int, int]:
    """Check a board's ``squares`` (cols, rows) and lengths, and store its ``square_m`` and
    ``margin_m`` as floats and its ``black``, ``white`` as checked reflectances (frozen
    dataclasses' ``__post_init__``); (cols, rows)."""
    square_m, margin_m = board.square_m, board.margin_m
    cols, rows = (int(n) for n in squares)
    if (cols, rows) != tuple(squares) or cols < 2 or rows < 2:
        raise InputError(f"squares must be two integers (cols, rows) >= 2, got {squares}")
    if not (np.isfinite(square_m) and square_m > 0):
        raise InputError(f"square_m must be a positive length in metres, got {square_m}")
    if not (np.isfinite(margin_m) and margin_m >= 0):
        raise InputError(f"margin_m must be a length >= 0 in metres, got {margin_m}")
    object.__setattr__(board, "square_m", float(square_m))
    object.__setattr__(board, "margin_m", float(margin_m))
    object.__setattr__(board, "black", require_reflectance(board.black, "black"))
    object.__setattr__(board, "white", require_reflectance(board.white, "white"))
    return cols, rows


def _board_size(squares: tuple[int, int], square_m: float, margin_m: float) -> tuple[float, float]:
    # rounded to 1e-12 m so that 40 × 25 mm reads 1.0, not 1.0000000000000002
    return (
        round(squares[0] * square_m + 2.0 * margin_m, 12),
        round(squares[1] * square_m + 2.0 * margin_m, 12),
    )


def _corner_ids(squares: tuple[int, int]) -> IntArray:
    cols, rows = squares
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    return np.stack([i.ravel(), j.ravel()], axis=1).astype(np.int64)


def _corners_uv(squares: tuple[int, int], square_m: float, margin_m: float) -> Array:
    ids = _corner_ids(squares)
    return margin_m + (ids[:, ::-1] + 1.0) * square_m


def _board_codes(squares: tuple[int, int], circles: NDArray[np.int8] | None) -> NDArray[np.int8]:
    """Per-square codes with a one-square ring for the margin (rows + 2, cols + 2).

    0 white, 1 black, 2 dark circle in a white square, 3 light circle in a black square.
    """
    cols, rows = squares
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    codes = np.zeros((rows + 2, cols + 2), dtype=np.int8)
    inner = ((r + c) % 2 == 0).astype(np.int8)
    if circles is not None:
        inner = np.where(circles > 0, circles + 1, inner).astype(np.int8)
    codes[1:-1, 1:-1] = inner
    codes.setflags(write=False)
    return codes


def _board_intensity(
    uv: Any,
    squares: tuple[int, int],
    square_m: float,
    margin_m: float,
    black: float,
    white: float,
    codes: NDArray[np.int8],
) -> Array:
    """Reflectance of a chessboard (with the circles in ``codes``) at ``uv`` (..., 2); NaN outside.

    ``codes`` comes from :func:`_board_codes`; one table look-up per point, then the exact
    circle test only for the points that fall in a square holding a circle.
    """
    u, v, lead = check_uv(uv)
    w, h = _board_size(squares, square_m, margin_m)
    lut = np.array([white, black, white, black])

    def block(u: Array, v: Array) -> Array:
        return _board_block(u, v, squares, square_m, margin_m, (w, h), lut, codes, black, white)

    return blockwise(block, u, v).reshape(lead)


def _board_block(
    u: Array,
    v: Array,
    squares: tuple[int, int],
    square_m: float,
    margin_m: float,
    size_m: tuple[float, float],
    lut: Array,
    codes: NDArray[np.int8],
    black: float,
    white: float,
) -> Array:
    cols, rows = squares
    inv = 1.0 / square_m
    x = (u - margin_m) * inv
    y = (v - margin_m) * inv
    with np.errstate(invalid="ignore"):  # NaN points: any index, masked below
        ci = np.clip(np.floor(x), -1, cols).astype(np.intp)
        ri = np.clip(np.floor(y), -1, rows).astype(np.intp)
    flat = ri * (cols + 2) + ci
    flat += cols + 3  # the ring: index (-1, -1) -> 0
    code = np.take(codes.ravel(), flat, mode="clip")
    out = np.take(lut, code)
    cand = np.flatnonzero(code >= 2)
    if cand.size:
        dx = x[cand] - (ci[cand] + 0.5)
        dy = y[cand] - (ri[cand] + 0.5)
        hit = cand[dx * dx + dy * dy < CIRCLE_RADIUS_SQUARES**2]
        out[hit] = np.where(code[hit] == 2, black, white)
    w, h = size_m
    outside = ~((u >= 0.0) & (u <= w) & (v >= 0.0) & (v <= h))
    out[outside] = np.nan
    return out


@dataclass(frozen=True, eq=False)
class Chessboard:
    """A plain chessboard, for the OpenCV sample set and multi-pose calibration.

    Examples
    --------
    >>> board = Chessboard((9, 6), square_m=0.025, margin_m=0.0)
    >>> board.squares, board.size_m, len(board.corners_uv())
    ((10, 7), (0.25, 0.175), 54)
    """

    #: Inner corners (cols, rows), as OpenCV's ``patternSize``; the board has
    #: (cols + 1) × (rows + 1) squares.
    pattern: tuple[int, int] = (9, 6)
    #: Square side, metres.
    square_m: float = 0.025
    #: White border around the squares, metres.
    margin_m: float = 0.025
    #: ``black``, ``white``: Reflectance of the black squares and of the paper.
    black: float = INK_BLACK
    #: See ``black`` above.
    white: float = PAPER_WHITE
    name: str = "chessboard"
    _codes: NDArray[np.int8] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cols, rows = _check_board(self, (self.pattern[0] + 1, self.pattern[1] + 1))
        object.__setattr__(self, "pattern", (cols - 1, rows - 1))
        object.__setattr__(self, "_codes", _board_codes((cols, rows), None))

    @property
    def squares(self) -> tuple[int, int]:
        """Number of squares (cols, rows)."""
        return self.pattern[0] + 1, self.pattern[1] + 1

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the printed board including the margin, metres."""
        return _board_size(self.squares, self.square_m, self.margin_m)

    def corner_ids(self) -> IntArray:
        """(row, col) of every inner corner, shape (rows·cols of ``pattern``, 2), row-major."""
        return _corner_ids(self.squares)

    def corners_uv(self) -> Array:
        """Inner-corner positions (N, 2), metres, in the order of :meth:`corner_ids`."""
        return _corners_uv(self.squares, self.square_m, self.margin_m)

    def object_points(self) -> Array:
        """Corners as OpenCV object points (N, 3), metres, first corner at the origin, z = 0."""
        uv = self.corners_uv() - (self.margin_m + self.square_m)
        return np.column_stack([uv, np.zeros(len(uv))])

    def intensity(self, uv: Any) -> Array:
        """Reflectance at chart points ``uv`` (..., 2) metres; NaN off the chart."""
        return _board_intensity(
            uv, self.squares, self.square_m, self.margin_m, self.black, self.white, self._codes
        )

    def keypoints(self) -> dict[str, Keypoints]:
        """``"corners"``: ids (row, col), uv metres."""
        return {"corners": Keypoints(self.corner_ids(), self.corners_uv())}


@dataclass(frozen=True, eq=False)
class VerificationChart:
    """The thesis's verification chart: a chessboard with four circle pairs (§1.2.2, §2.2).

    Examples
    --------
    >>> chart = VerificationChart()           # 40 × 28 squares of 25 mm
    >>> chart.size_m, len(chart.corners_uv())  # 1.0 × 0.7 m + 25 mm margin; 39 × 27 corners
    ((1.05, 0.75), 1053)
    >>> [p.name for p in chart.circle_pairs]
    ['h_dark', 'v_light', 'v_dark', 'h_light']
    """

    #: Number of squares (cols, rows); at least (10, 8) so the pairs fit with a ring around.
    squares: tuple[int, int] = (40, 28)
    #: Square side, metres.
    square_m: float = 0.025
    #: White border around the squares, metres.
    margin_m: float = 0.025
    #: ``black``, ``white``: Reflectance of the black squares and of the paper.
    black: float = INK_BLACK
    #: See ``black`` above.
    white: float = PAPER_WHITE
    name: str = "verification"
    _codes: NDArray[np.int8] = field(init=False, repr=False)
    _pairs: tuple[CirclePair, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cols, rows = _check_board(self, self.squares)
        if cols < 10 or rows < 8:
            raise InputError(
                f"a verification chart needs at least 10 × 8 squares (cols, rows) for its "
                f"circle pairs, got {cols} × {rows}; use Chessboard for small boards"
            )
        object.__setattr__(self, "squares", (cols, rows))
        r0, c0 = rows // 2, cols // 2
        if (r0 + c0) % 2:  # keep the centre square black so the polarities hold
            c0 -= 1
        table = np.zeros((rows, cols), dtype=np.int8)
        pairs = []
        for name, axis, polarity, (ra, ca, rb, cb) in _PAIR_LAYOUT:
            sq = np.array([[r0 + ra, c0 + ca], [r0 + rb, c0 + cb]], dtype=np.int64)
            table[sq[:, 0], sq[:, 1]] = 1 if polarity == "dark" else 2
            centers = self.margin_m + (sq[:, ::-1] + 0.5) * self.square_m
            radius = CIRCLE_RADIUS_SQUARES * self.square_m
            pairs.append(CirclePair(name, centers, radius, polarity, axis, sq))
        object.__setattr__(self, "_codes", _board_codes((cols, rows), table))
        object.__setattr__(self, "_pairs", tuple(pairs))

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the printed chart including the margin, metres."""
        return _board_size(self.squares, self.square_m, self.margin_m)

    @property
    def circle_pairs(self) -> tuple[CirclePair, ...]:
        """The four circle pairs, in the order h_dark, v_light, v_dark, h_light."""
        return self._pairs

    @property
    def pattern(self) -> tuple[int, int]:
        """Inner corners (cols, rows), as OpenCV's ``patternSize``."""
        return self.squares[0] - 1, self.squares[1] - 1

    def corner_ids(self) -> IntArray:
        """(row, col) of every inner corner, shape ((rows − 1)·(cols − 1), 2), row-major."""
        return _corner_ids(self.squares)

    def corners_uv(self) -> Array:
        """Inner-corner positions (N, 2), metres, in the order of :meth:`corner_ids`."""
        return _corners_uv(self.squares, self.square_m, self.margin_m)

    def intensity(self, uv: Any) -> Array:
        """Reflectance at chart points ``uv`` (..., 2) metres; NaN off the chart.

        >>> chart = VerificationChart()
        >>> s, m = chart.square_m, chart.margin_m
        >>> chart.intensity([[m + 0.5 * s, m + 0.5 * s], [m + 1.5 * s, m + 0.5 * s],
        ...                  [0.01, 0.01], [-0.01, 0.3]]).tolist()
        [0.05, 0.95, 0.95, nan]
        """
        return _board_intensity(
            uv,
            self.squares,
            self.square_m,
            self.margin_m,
            self.black,
            self.white,
            self._codes,
        )

    def keypoints(self) -> dict[str, Keypoints]:
        """``"corners"``: ids (row, col); ``"circles"``: ids (pair, circle) in pair order."""
        ids = np.array([[p, k] for p in range(len(self._pairs)) for k in range(2)])
        uv = np.concatenate([p.centers_uv for p in self._pairs])
        return {
            "corners": Keypoints(self.corner_ids(), self.corners_uv()),
            "circles": Keypoints(ids, uv),
        }
