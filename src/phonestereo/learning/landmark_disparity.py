"""Landmark disparity: a face's disparity at its eyes, with its IPD depth (thesis §4.1.3, §3.6).

The learning flow's "landmark disparity estimation" block (Fig. 4-3, 4-4):

1. landmarks of each face in the wide and in the raw tele image (the tele sees faces ×zoom
   larger), their pupils mapped into the rectified frame (``canonical`` mode, §3.3);
2. (steps 2–3 in :mod:`~phonestereo.learning.face_pairing`) the depth of each wide face
   from its IPD (eq. 11: :func:`~phonestereo.learning.ipd.
   fit_face_plane` for a printed chart, :func:`~phonestereo.learning.ipd.face_depth` for real
   heads) and the disparity it predicts, ``d_expected = f·B/Z`` (eq. 4, Z along the rectified
   axis);
3. wide ↔ tele faces matched by the landmark disparity: the non-disparity error ``e`` of the
   pupils must be small and their disparity near ``d_expected`` (a gate loose enough for the
   naive calibration's ~30 % error, tight enough to separate faces);
   a wide face without a tele partner (Face Mesh fails on a face that fills a ×5 tele or is
   cut by its border; the guide missed it) is searched from its own rectified pupils, one
   NCC window per eye over the same gate, when both eyes are in the tele's image;
4. the disparity refined around both pupils ("peak refinement"): a grid of windows over each eye
   region of the rectified wide image, integer NCC search in the rectified tele image
   (:func:`~phonestereo.features.search.ncc_search`) then Lucas–Kanade sub-pixel refinement
   (:func:`~phonestereo.features.subpixel.refine_lk`) with the Cramér–Rao σ per window
   (:func:`~phonestereo.features.crlb.match_sigma`); their robust weighted mean is the face's d.

A face that cannot be measured (no tele partner, no converged window) is listed with its reason,
never dropped silently.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.features.crlb import match_sigma
from phonestereo.features.landmarks.base import FaceResult
from phonestereo.features.search import ncc_search
from phonestereo.features.subpixel import PREFILTER_MARGIN, refine_lk
from phonestereo.learning.eye_images import FaceReach, RectifiedPair, eye_step, prepare
from phonestereo.learning.face_pairing import DepthMode, ipd_depths, match_faces, pupils_px
from phonestereo.learning.ipd import IPD_M
from phonestereo.learning.tele_search import search_start
from phonestereo.rectification import Rectification

F64 = NDArray[np.float64]

__all__ = [
    "DepthMode",
    "FaceDisparity",
    "LandmarkDisparityResult",
    "ipd_depths",
    "landmark_disparity",
    "match_faces",
]


@dataclass(frozen=True)
class FaceDisparity:
    """One wide face matched into the tele, its refined disparity and its IPD depth."""

    #: ``wide_index``, ``tele_index``: Indices of the face in the wide and tele :class:`FaceResult`
    #: (tele −1: no tele landmarks, the face was searched from its wide pupils).
    wide_index: int
    #: See ``wide_index`` above.
    tele_index: int
    #: ``x_px``, ``y_px``: Pupil midpoint in the rectified wide image, pixels.
    x_px: float
    #: See ``x_px`` above.
    y_px: float
    #: ``d_px``, ``sigma_d_px``: Refined disparity at the pupil midpoint and its standard deviation,
    #: pixels.
    d_px: float
    #: See ``d_px`` above.
    sigma_d_px: float
    #: Refined non-disparity error (median over windows), pixels.
    e_px: float
    #: ``d_landmark_px``, ``e_landmark_px``: The same from the pupil landmarks alone (the matching
    #: step), pixels.
    d_landmark_px: float
    #: See ``d_landmark_px`` above.
    e_landmark_px: float
    #: Z of the pupil midpoint from the IPD (eq. 11), along the rectified axis, metres.
    depth_ipd_m: float
    #: ``f·B / depth_ipd_m`` (eq. 4), pixels.
    d_expected_px: float
    #: Windows that converged and survived the outlier test.
    n_windows: int
    #: Median ZNCC of those windows at the solution.
    zncc: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly record (floats rounded to 1e-4)."""
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in vars(self).items()}


@dataclass(frozen=True)
class LandmarkDisparityResult:
    """The measured faces of one capture; ``reason`` says why there are none.

    ``unmatched`` holds ``(wide_index, reason)`` for every wide face not measured.
    """

    faces: tuple[FaceDisparity, ...]
    n_wide: int
    n_tele: int
    reason: str = ""
    unmatched: tuple[tuple[int, str], ...] = ()

    def __len__(self) -> int:
        return len(self.faces)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly summary."""
        return {
            "n_wide": self.n_wide,
            "n_tele": self.n_tele,
            "reason": self.reason,
            "faces": [f.to_dict() for f in self.faces],
            "unmatched": [{"wide_index": i, "reason": r} for i, r in self.unmatched],
        }


@dataclass(frozen=True)
class _EyeWindows:
    """The searched windows of one face: centres (n, 2), offsets from the pupil midpoint
    (n, 2), the eye each window is about (n,: 0 or 1), integer-search (d, e) (n,), window
    radius and grid step, px."""

    xy: NDArray[np.int64]
    offset: F64
    eye: NDArray[np.int64]
    d0: F64
    e0: F64
    radius: int
    step: int


def _eye_windows(img: RectifiedPair, pupils: F64, d0: float, e0: float) -> _EyeWindows | None:
    """A 5 × 5 grid of windows around each rectified pupil (2, 2), searched in the tele
    within ±4 px of the landmark disparity ``d0``; None when no window could be searched."""
    ipd = float(np.linalg.norm(pupils[1] - pupils[0]))
    step = eye_step(ipd)
    r = int(np.clip(round(0.12 * ipd), 6, 12))  # ≤ eye_images.MAX_RADIUS
    k = np.arange(-2, 3) * step
    grid = np.stack(np.meshgrid(k, k), axis=-1).reshape(-1, 2)
    xy = np.rint(pupils[:, None, :] + grid[None]).reshape(-1, 2).astype(np.int64)
    offset = (xy - pupils.mean(axis=0)).astype(np.float64)  # window centre − pupil midpoint
    eye = np.repeat(np.arange(2), len(grid))
    h, w = img.left.shape
    m = r + PREFILTER_MARGIN
    inside = (xy[:, 0] >= m) & (xy[:, 0] < w - m) & (xy[:, 1] >= m) & (xy[:, 1] < h - m)
    xy, offset, eye = xy[inside], offset[inside], eye[inside]
    if len(xy) == 0:
        return None
    lo, hi = int(np.floor(d0 - 4.0)), int(np.ceil(d0 + 4.0))
    # No left-right check (half the matchTemplate calls): the ±4 px band around the face's
    # own landmark disparity and the robust fit of _fit_face already reject mismatches.
    s = ncc_search(
        img.left, img.right, xy, radius=r, min_d=lo, max_d=hi,
        row_tolerance=int(np.ceil(abs(e0))) + 2, lr_min_score=np.inf,
    )
    ok = s.searched & ~s.at_edge & np.isfinite(s.d0)
    if not ok.any():
        return None
    return _EyeWindows(xy[ok], offset[ok], eye[ok], s.d0[ok], s.e0[ok], r, step)


def _refine_faces(
    img: RectifiedPair, faces: list[tuple[F64, float, float]], *, min_zncc: float
) -> list[tuple[float, float, float, int, float]]:
    """(d, σ_d, e, n, zncc) per face (rectified pupils (2, 2), landmark d, landmark e).

    The windows of all faces with the same window radius are refined in one
    :func:`~phonestereo.features.subpixel.refine_lk` call (each window iterates on its own,
    so batching changes no number; it saves the per-call overhead).
    """
    empty = (np.nan, np.nan, np.nan, 0, np.nan)
    wins = [_eye_windows(img, *f) for f in faces]
    out: list[tuple[float, float, float, int, float]] = [empty] * len(faces)
    found = {k: w for k, w in enumerate(wins) if w is not None}
    for r in sorted({w.radius for w in found.values()}):
        idx = [k for k, w in found.items() if w.radius == r]
        group = [found[k] for k in idx]
        ref = refine_lk(
            img.left, None, img.right_coef,
            np.concatenate([w.xy for w in group]), np.concatenate([w.d0 for w in group]),
            np.concatenate([w.e0 for w in group]), radius=r, slant=False,
        )
        sd, _, _ = match_sigma(
            ref.cov_unit, ref.residual_var, ref.gain, img.sigma_left, img.sigma_right
        )
        good = ref.converged & (ref.zncc >= min_zncc) & np.isfinite(sd) & (sd > 0)
        bounds = np.cumsum(np.array([0] + [len(w.xy) for w in group], dtype=np.int64))
        for k, w, a, b in zip(idx, group, bounds[:-1], bounds[1:], strict=True):
            g = good[a:b]
            out[k] = _fit_face(
                ref.d[a:b][g], sd[a:b][g], ref.e[a:b][g], ref.zncc[a:b][g], w.offset[g],
                w.eye[g], w,
            )
    return out


def _eye_inliers(d: F64, sd: F64, eye: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Windows on their own eye's disparity (n,): eyelashes, occlusions and wrong peaks out.

    Each eye is tested about its own median: a slanted face's eyes differ by up to ~2 px at
    1 m, and a test about the face's median would drop the eye with fewer windows whole.
    """
    keep = np.ones(len(d), dtype=bool)
    for k in (0, 1):
        idx = np.flatnonzero(eye == k)
        for _ in range(3):
            if len(idx) < 3:
                break
            med = np.median(d[idx])
            mad = 1.4826 * np.median(np.abs(d[idx] - med))
            ok = np.abs(d[idx] - med) <= np.maximum(3.0 * mad, 3.0 * sd[idx]) + 0.02
            if ok.all():
                break
            keep[idx[~ok]] = False
            idx = idx[ok]
    return keep


def _fit_face(
    d: F64, sd: F64, e: F64, z: F64, off: F64, eye: NDArray[np.int64], w: _EyeWindows
) -> tuple[float, float, float, int, float]:
    """(d, σ_d, e, n, zncc) of one face from its refined windows (the robust fit).

    The disparity at the pupil midpoint needs both eyes: one eye's windows measure the face
    ~IPD/2 off the midpoint, by half the face's disparity gradient (up to ~1 px on a slanted
    chart at 1 m), which no σ of those windows carries. A face with one eye left is not
    measured: n = −1 (n = 0: no window left).
    """
    keep = _eye_inliers(d, sd, eye)
    d, sd, e, z, off, eye = d[keep], sd[keep], e[keep], z[keep], off[keep], eye[keep]
    if not ((eye == 0).any() and (eye == 1).any()):
        return np.nan, np.nan, np.nan, -1 if len(d) else 0, np.nan
    wts = 1.0 / sd**2
    # d at the pupil midpoint: a weighted plane d = a + b·Δx + c·Δy with enough windows (a
    # slanted face), else a + b·Δx (the eyes sit about the midpoint along the eye line)
    design = np.column_stack([np.ones(len(d)), off if len(d) >= 6 else off[:, :1]])
    sw = np.sqrt(wts)
    coef, *_ = np.linalg.lstsq(design * sw[:, None], d * sw, rcond=None)
    cov = np.linalg.pinv(design.T @ (design * wts[:, None]))
    # overlapping windows share pixels: inflate by the number of windows covering each pixel
    # (on rendered charts this makes (d − d_true) / σ_d ≈ 1 rms; without it ≈ 2.3)
    overlap = max(1.0, ((2 * w.radius + 1) / w.step) ** 2)
    resid = d - design @ coef
    scatter = float(np.sqrt(np.sum(wts * resid**2) / np.sum(wts) / max(len(d) - 1, 1)))
    sigma = max(float(np.sqrt(cov[0, 0] * overlap)), scatter)
    return float(coef[0]), sigma, float(np.median(e)), len(d), float(np.median(z))


def landmark_disparity(
    rect: Rectification,
    image_wide: Any,
    image_tele: Any,
    faces_wide: FaceResult,
    faces_tele: FaceResult,
    *,
    ipd_m: float = IPD_M,
    depth_mode: DepthMode = "chart",
    chart_pitch_m: float | None = None,
    max_e_px: float = 10.0,
    d_tol_px: float = 4.0,
    d_tol_rel: float = 0.35,
    min_zncc: float = 0.8,
    d_offset_px: float = 0.0,
) -> LandmarkDisparityResult:
    """Per-face disparity at the eyes and the disparity its IPD depth predicts (§4.1.3).

    Parameters
    ----------
    rect : Rectification
        Of the capture's calibration (``canonical`` mode recommended, §3.3).
    image_wide, image_tele : ndarray, shape (H, W) or (H, W, 3), uint8
        The raw images (as taken: the tele at its own zoom).
    faces_wide, faces_tele : FaceResult
        Landmarks of the raw wide and the raw tele image (e.g. ``MediaPipeBackend``).
    ipd_m : float
        True IPD, metres (63 mm for the face chart; a population mean for real faces).
    depth_mode : {"chart", "face"}
        See :func:`ipd_depths`.
    chart_pitch_m : float, optional
        The face chart's grid pitch (``"chart"``), see :func:`ipd_depths`.
    max_e_px, d_tol_px, d_tol_rel : float
        Matching gates, see :func:`match_faces`.
    min_zncc : float
        Windows below this ZNCC after refinement are not used.
    d_offset_px : float
        How far the calibration's disparities are known to read below the truth (a learned
        correction's typical value, px): the gates centre on ``f·B/Z_IPD − d_offset_px``.

    Returns
    -------
    LandmarkDisparityResult
        Faces with d, σ_d, e, the IPD depth and f·B/Z_IPD; ``reason`` when none was measured.
    """
    if not faces_wide.found:
        return LandmarkDisparityResult((), 0, len(faces_tele), f"wide: {faces_wide.reason}")
    pw = rect.points_wide(pupils_px(faces_wide))  # (Nw, 2, 2) rectified
    pt = rect.points_tele(pupils_px(faces_tele)).reshape(-1, 2, 2)  # (Nt, 2, 2)
    diff = pw[:, None] - pt[None]  # (Nw, Nt, 2 pupils, 2)
    d_lm, e_lm = diff[..., 0].mean(axis=2), diff[..., 1].mean(axis=2)
    z, d_exp = ipd_depths(faces_wide, rect, ipd_m, depth_mode, chart_pitch_m)
    pairs = match_faces(
        d_lm + d_offset_px, e_lm, d_exp, max_e_px=max_e_px, d_tol_px=d_tol_px,
        d_tol_rel=d_tol_rel,
    )
    matched = {i for i, _ in pairs}
    # Faces without a tele partner (Face Mesh failed on a face that fills the tele, the face
    # is cut by the tele's border, the guide missed it) are searched from the wide pupils.
    lone = [i for i in range(len(faces_wide)) if i not in matched and np.isfinite(d_exp[i])]
    # the pair is resampled where the searches below may read: the eye windows ±4 px about
    # a pair's landmark disparity (rows ± |e| + 2), a lone face's whole gate (rows ± max_e)
    reach = [FaceReach(pw[i], d_lm[i, j] - 5.0, d_lm[i, j] + 5.0, abs(e_lm[i, j]) + 3.0)
             for i, j in pairs]
    # a lone face's gate: d_expected (less the known offset) ± the match_faces tolerance
    tol = d_tol_px + d_tol_rel * np.abs(d_exp)
    gates = np.column_stack([d_exp - d_offset_px - tol, d_exp - d_offset_px + tol])
    for i in lone:
        reach.append(FaceReach(pw[i], gates[i, 0] - 5.0, gates[i, 1] + 5.0, max_e_px + 3.0))
    img = prepare(rect, image_wide, image_tele, reach) if pairs or lone else None
    out: list[FaceDisparity] = []
    unmatched: list[tuple[int, str]] = []
    starts: list[tuple[int, int, float, float]] = [(i, j, d_lm[i, j], e_lm[i, j]) for i, j in pairs]
    tele_why = f"tele: {faces_tele.reason}; " if not faces_tele.found else ""
    for i in range(len(faces_wide)):
        if i in matched:
            continue
        if not np.isfinite(d_exp[i]):
            unmatched.append((i, "no IPD depth"))
            continue
        assert img is not None
        start, why = search_start(rect, img.left, img.right, pw[i],
                                  (float(gates[i, 0]), float(gates[i, 1])), max_e_px)
        if start is None:
            unmatched.append((i, tele_why + why))
        else:
            starts.append((i, -1, start[0], start[1]))
    refined = (
        []
        if img is None
        else _refine_faces(img, [(pw[i], d0, e0) for i, _, d0, e0 in starts], min_zncc=min_zncc)
    )
    for (i, j, d0, e0), (d, sd, e, n, zn) in zip(starts, refined, strict=True):
        if n <= 0:
            why = "no eye window converged in the tele (blur, occlusion, edge)"
            if n < 0:
                why = "one eye only in the tele after the outlier test (its midpoint needs both)"
            unmatched.append((i, why))
            continue
        mid = pw[i].mean(axis=0)
        out.append(
            FaceDisparity(
                i,
                j,
                float(mid[0]),
                float(mid[1]),
                d,
                sd,
                e,
                float(d0),
                float(e0),
                float(z[i]),
                float(d_exp[i]),
                n,
                zn,
            )
        )
    reason = (
        ""
        if out
        else "no face measured in both cameras: " + "; ".join(sorted({r for _, r in unmatched}))
    )
    return LandmarkDisparityResult(
        tuple(out), len(faces_wide), len(faces_tele), reason, tuple(sorted(unmatched))
    )
