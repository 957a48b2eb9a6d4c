"""The single-shot three-plane calibration chart of thesis §1.3.2.

"A chart consisting of 3 flat chessboard planes combined together": one capture of it gives
non-coplanar corners in a single chart frame, enough for the intrinsics of each camera and
the stereo extrinsics (at the price of covering only part of the image, §1.3.3 "Chart").

Layout (a concave corner seen from the front, every plane visible without occlusion):

- ``left``  wall: a chessboard whose right edge stands on the vertical hinge and whose left
  edge comes towards the viewer (yawed by ``wall_deg``);
- ``right`` wall: its mirror image, the left edge on the hinge;
- ``floor``: below both walls, its bottom edge coming towards the viewer (pitched by
  ``floor_deg``).

The three boards have different inner-corner patterns whose column + row counts are odd, so a
detector can tell them apart by size and resolve OpenCV's 180° ordering ambiguity by the
colour of the squares (square (0, 0) of every board is black).

Chart frame: x right, y down, z away from the viewer (into the chart), like the frame of a
planar chart; the origin is the centre of the chart's frontal bounding box, so a chart posed
with its origin on a camera's axis is centred in that camera's image. Each plane's own frame
is the :class:`~phonestereo.charts.verification.Chessboard` chart frame (origin at its top-left
corner, u right, v down, z into the board), placed by ``T_chart_plane``.

Corner ids: plane k's corner (row, col) has id ``1000·k + row·cols + col`` (unique over the
chart, so wide ↔ tele corners are matched by id).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from phonestereo.charts.base import Array, IntArray
from phonestereo.charts.verification import Chessboard
from phonestereo.errors import InputError
from phonestereo.geometry import Transform

#: Id offset between planes: plane k's corners have ids 1000·k + row·cols + col.
PLANE_ID_STRIDE = 1000

#: Inner-corner patterns (cols, rows) of the left wall, the right wall and the floor.
PATTERNS: tuple[tuple[int, int], ...] = ((7, 6), (6, 5), (9, 4))
PLANE_NAMES: tuple[str, ...] = ("left", "right", "floor")


@dataclass(frozen=True, eq=False)
class ChartPlane:
    """One flat board of the three-plane chart."""

    #: ``"left"``, ``"right"`` or ``"floor"``.
    name: str
    #: The printed board (its own chart frame: origin top-left, u right, v down).
    board: Chessboard
    #: Maps the board's frame into the three-plane chart frame (metres).
    T_chart_plane: Transform
    #: Added to ``row·cols + col`` to make the corner ids unique over the chart.
    id_offset: int

    def corner_ids(self) -> IntArray:
        """Chart-wide ids of the board's inner corners (rows·cols,), row-major (OpenCV order)."""
        cols, rows = self.board.pattern
        return np.arange(cols * rows, dtype=np.int64) + self.id_offset

    def corners_chart(self) -> Array:
        """Inner corners in the three-plane chart frame (rows·cols, 3), metres, row-major."""
        uv = self.board.corners_uv()
        return self.T_chart_plane.apply(np.column_stack([uv, np.zeros(len(uv))]))


def _rot_y(angle: float) -> Array:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_x(angle: float) -> Array:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


@dataclass(frozen=True, eq=False)
class ThreePlaneChart:
    """Three chessboards in one rigid frame: the thesis's single-shot calibration chart (§1.3.2).

    Examples
    --------
    >>> chart = ThreePlaneChart()               # 12 mm squares: fits the x3 tele at 0.65 m
    >>> [p.board.pattern for p in chart.planes], len(chart.corner_ids())
    ([(7, 6), (6, 5), (9, 4)], 108)
    >>> bool(np.ptp(chart.object_points()[:, 2]) > 0.04)   # 4 cm of depth: not coplanar
    True
    """

    #: Square side of all three boards, metres (each board has a one-square white margin).
    square_m: float = 0.012
    #: Yaw of each wall towards the viewer, degrees (0: one flat board; < 80).
    wall_deg: float = 35.0
    #: Pitch of the floor towards the viewer, degrees (< 80).
    floor_deg: float = 45.0
    #: Clearance between the boards' outlines (seen from the front), metres.
    gap_m: float = 0.006
    name: str = "three-plane"
    _planes: tuple[ChartPlane, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        s = float(self.square_m)
        if not (np.isfinite(s) and s > 0):
            raise InputError(f"square_m must be a positive length in metres, got {s}")
        for label, angle in (("wall_deg", self.wall_deg), ("floor_deg", self.floor_deg)):
            if not (np.isfinite(angle) and 0 <= angle < 80):
                raise InputError(f"{label} must be in [0, 80) degrees, got {angle}")
        if not (np.isfinite(self.gap_m) and self.gap_m >= 0):
            raise InputError(f"gap_m must be a length >= 0 in metres, got {self.gap_m}")
        boards = [
            Chessboard(p, square_m=s, margin_m=s, name=n)
            for p, n in zip(PATTERNS, PLANE_NAMES, strict=True)
        ]
        th, ph, g = np.deg2rad(self.wall_deg), np.deg2rad(self.floor_deg), float(self.gap_m)
        (wl, hl), (_, hr), (wf, _) = (b.size_m for b in boards)
        # Walls: the hinge is the vertical line x = 0, z = 0, walls from y = 0 down.
        left = Transform(_rot_y(-th), _rot_y(-th) @ np.array([-wl, 0.0, 0.0]) + [-g / 2, 0, 0])
        right = Transform(_rot_y(th), np.array([g / 2, 0.0, 0.0]))
        # Floor: its top edge g below the lower wall, centred on the hinge.
        floor = Transform(_rot_x(-ph), np.array([-wf / 2, max(hl, hr) + g, 0.0]))
        poses = [left, right, floor]
        # Centre the frontal bounding box of the three outlines on the chart origin.
        outline = np.concatenate([_outline(b, T) for b, T in zip(boards, poses, strict=True)])
        mid = 0.5 * (outline[:, :2].min(axis=0) + outline[:, :2].max(axis=0))
        shift = Transform(np.eye(3), np.array([-mid[0], -mid[1], 0.0]))
        planes = tuple(
            ChartPlane(n, b, shift @ T, PLANE_ID_STRIDE * k)
            for k, (n, b, T) in enumerate(zip(PLANE_NAMES, boards, poses, strict=True))
        )
        object.__setattr__(self, "square_m", s)
        object.__setattr__(self, "_planes", planes)

    @property
    def planes(self) -> tuple[ChartPlane, ...]:
        """The three boards, in the order left wall, right wall, floor."""
        return self._planes

    def plane(self, name: str) -> ChartPlane:
        """A board by name (InputError naming the three if unknown)."""
        for p in self._planes:
            if p.name == name:
                return p
        raise InputError(f"no plane {name!r}; the planes are {list(PLANE_NAMES)}")

    def corner_ids(self) -> IntArray:
        """Chart-wide corner ids (N,), plane by plane, row-major within a plane."""
        return np.concatenate([p.corner_ids() for p in self._planes])

    def object_points(self) -> Array:
        """Corner positions (N, 3) in the chart frame, metres, ordered as :meth:`corner_ids`."""
        return np.concatenate([p.corners_chart() for p in self._planes])

    def object_points_for(self, ids: IntArray) -> Array:
        """Chart-frame positions (K, 3) of the corners with the given chart-wide ids.

        >>> chart = ThreePlaneChart()
        >>> bool(np.allclose(chart.object_points_for(chart.corner_ids()), chart.object_points()))
        True
        """
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        all_ids = self.corner_ids()
        pos = np.searchsorted(all_ids, ids)
        pos = np.clip(pos, 0, len(all_ids) - 1)
        bad = all_ids[pos] != ids
        if bad.any():
            raise InputError(
                f"ids {ids[bad][:5].tolist()} are not corners of the three-plane chart; ids are "
                f"{PLANE_ID_STRIDE}·plane + row·cols + col"
            )
        return self.object_points()[pos]

    def outline_chart(self) -> Array:
        """The 4 outline corners of each board (12, 3) in the chart frame, metres."""
        return np.concatenate([_outline(p.board, p.T_chart_plane) for p in self._planes])

    @property
    def extent_m(self) -> tuple[float, float]:
        """(width, height) of the chart's frontal bounding box, metres."""
        o = self.outline_chart()
        w, h = np.ptp(o[:, 0]), np.ptp(o[:, 1])
        return float(w), float(h)


def _outline(board: Chessboard, T: Transform) -> Array:
    w, h = board.size_m
    return T.apply(np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], dtype=np.float64))
