"""Refocus fixes (thesis §3.5): focus-fail detection, disparity clusters, refocus averaging and
the flat-scene homography → residual distortion → scale method.

* :func:`sharpness` and :func:`detect_focus_failures` — §3.5.1 "focus fail": a capture whose
  ROI is far less sharp (variance of the Laplacian) than the stack's median missed focus;
* :func:`cluster_disparities` — §3.5.2 fix option: group matches by disparity (one cluster per
  depth) so each depth gets its own W-T scale
  (:func:`~phonestereo.fixes.wt_scale.fit_wt_scale_per_cluster`);
* :func:`average_disparities` and :func:`averaging_trials` — §3.5.3 option 2 ("Wide-Tele
  matching and average disparity"): per corner / per match, the mean disparity over N refocus
  attempts (Figure 3-21, Table 3);
* :func:`flat_scene_scale` — §3.5.2 (Figures 3-14 / 3-15): for a flat scene, first the
  homography between the rectified tele and wide points (``cv2.findHomography``), then the
  residual radial distortion left after it, then the W-T scale of the tele points corrected
  for that residual distortion only (not warped by the homography).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError
from phonestereo.fixes.focus import MIN_POINTS
from phonestereo.fixes.wt_scale import WTScale, fit_wt_scale
from phonestereo.geometry.checks import Array, as_points

#: A capture is a focus fail when its sharpness is below this fraction of the stack's median.
FOCUS_FAIL_RELATIVE = 0.5
#: Homography ↔ residual-distortion alternations of :func:`flat_scene_scale`.
FLAT_ITERATIONS = 5


def sharpness(image: Any, roi: tuple[int, int, int, int] | None = None) -> float:
    """Variance of the Laplacian of an image (or its ROI): a focus metric (thesis §3.5.1).

    Parameters
    ----------
    image : array_like, shape (H, W) or (H, W, 3)
        Grayscale or BGR image, any numeric type (values used as given).
    roi : (x, y, w, h), optional
        Pixel rectangle to measure (clipped to the image).

    Returns
    -------
    float
        Var(∇²I) in squared grey levels per pixel²; larger is sharper.

    Examples
    --------
    A blurred chessboard is far less sharp than the sharp one:

    >>> board = (np.indices((64, 64)).sum(0) // 8 % 2 * 255).astype(np.uint8)
    >>> sharp, blur = sharpness(board), sharpness(cv2.GaussianBlur(board, (0, 0), 2.0))
    >>> bool(blur < 0.1 * sharp)
    True
    """
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img.astype(np.float32), cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or min(img.shape) < 3:
        raise ShapeError(f"image must be (H, W) or (H, W, 3) and at least 3×3, got {img.shape}")
    if roi is not None:
        x, y, w, h = (int(v) for v in roi)
        x0, y0 = max(x, 0), max(y, 0)
        img = img[y0 : max(y + h, y0), x0 : max(x + w, x0)]
        if min(img.shape) < 3:
            raise InputError(f"roi {roi} leaves < 3×3 pixels inside the image; pass a larger one")
    lap = cv2.Laplacian(img.astype(np.float64), cv2.CV_64F, ksize=3)
    return float(lap.var())


@dataclass(frozen=True)
class FocusVerdict:
    """Focus-fail decision of one capture of a stack."""

    #: The capture's focus metric (:func:`sharpness`).
    sharpness: float
    #: Sharpness / the stack's median sharpness.
    relative: float
    #: True when ``relative`` < the threshold (the capture missed focus).
    failed: bool
    #: Why it failed (empty when it did not).
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return asdict(self)


def detect_focus_failures(
    scores: Sequence[float], *, min_relative: float = FOCUS_FAIL_RELATIVE
) -> list[FocusVerdict]:
    """Focus-fail detection over a refocus stack: sharpness relative to the stack's median.

    Parameters
    ----------
    scores : sequence of float, length M >= 1
        :func:`sharpness` of each capture (same ROI, same camera).
    min_relative : float
        A capture below ``min_relative`` × median failed (default 0.5).

    Examples
    --------
    >>> [v.failed for v in detect_focus_failures([410.0, 395.0, 120.0, 402.0])]
    [False, False, True, False]
    """
    s = np.asarray(scores, dtype=np.float64).reshape(-1)
    if s.size == 0 or not np.isfinite(s).all() or (s < 0).any():
        raise InputError(f"scores must be >= 1 finite non-negative sharpness values, got {s}")
    if not 0.0 < min_relative < 1.0:
        raise InputError(f"min_relative must be in (0, 1), got {min_relative}")
    med = float(np.median(s))
    rel = s / med if med > 0 else np.ones_like(s)
    return [
        FocusVerdict(
            float(v), float(r), bool(r < min_relative),
            f"sharpness {r:.2f}× the stack's median (< {min_relative}): focus missed"
            if r < min_relative else "",
        )
        for v, r in zip(s, rel, strict=True)
    ]


def cluster_disparities(
    d: Any, *, gap_px: float = 1.0, min_size: int = MIN_POINTS
) -> NDArray[np.int64]:
    """Disparity clusters (one per depth, thesis §3.5.2): split the sorted d at gaps > gap_px.

    Parameters
    ----------
    d : array_like, shape (N,)
        Disparities, pixels (NaN allowed).
    gap_px : float
        Smallest gap between consecutive sorted disparities that separates two clusters.
    min_size : int
        Clusters with fewer members are labelled −1 (too few for a W-T scale).

    Returns
    -------
    labels : ndarray, shape (N,), int64
        0 for the largest-disparity (nearest) cluster, then 1, 2, ...; −1 for NaN or small.

    Examples
    --------
    Two charts, at 1 m (d ≈ 18 px) and 2 m (d ≈ 9 px):

    >>> d = np.r_[np.full(8, 18.1), np.full(10, 9.05), np.nan]
    >>> cluster_disparities(d).tolist()
    [0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, -1]
    """
    v = np.asarray(d, dtype=np.float64).reshape(-1)
    labels = np.full(v.shape, -1, dtype=np.int64)
    ok = np.flatnonzero(np.isfinite(v))
    if ok.size == 0:
        return labels
    order = ok[np.argsort(-v[ok])]
    breaks = np.flatnonzero(-np.diff(v[order]) > gap_px) + 1
    groups = [g for g in np.split(order, breaks) if len(g) >= min_size]
    for k, g in enumerate(groups):
        labels[g] = k
    return labels


def average_disparities(d_stack: Any, attempts: Any = None) -> Array:
    """Per corner / match, the mean disparity over refocus attempts (§3.5.3 option 2).

    Parameters
    ----------
    d_stack : array_like, shape (M, K)
        Disparity of K corners in M attempts, pixels (NaN where not seen).
    attempts : array_like of int, optional
        The attempts to average (default all).

    Returns
    -------
    ndarray, shape (K,)
        Mean over the attempts that saw each corner (NaN if none did).

    Examples
    --------
    >>> average_disparities([[12.0, 8.0], [12.2, np.nan], [11.9, 8.1]], [0, 1]).tolist()
    [12.1, 8.0]
    """
    d = np.asarray(d_stack, dtype=np.float64)
    if d.ndim != 2:
        raise ShapeError(f"d_stack must be (M attempts, K corners), got shape {d.shape}")
    if attempts is not None:
        d = d[np.asarray(attempts, dtype=np.int64)]
    n = np.isfinite(d).sum(axis=0)
    total = np.where(np.isfinite(d), d, 0.0).sum(axis=0)
    return np.asarray(np.where(n > 0, total / np.maximum(n, 1), np.nan))


def averaging_trials(d_stack: Any, n: int, trials: int = 200, seed: int = 0) -> Array:
    """Averages of ``n`` attempts chosen at random (Figure 3-21): (trials, K), pixels.

    Each trial draws ``n`` distinct attempts of the M (``numpy`` generator seeded ``seed``) and
    averages them per corner (:func:`average_disparities`).

    Examples
    --------
    >>> d = np.array([[10.0], [10.2], [9.8], [10.1], [9.9]])
    >>> a1, a5 = averaging_trials(d, 1, 50), averaging_trials(d, 5, 50)
    >>> bool(np.ptp(a5) < 1e-12 < np.ptp(a1))
    True
    """
    d = np.asarray(d_stack, dtype=np.float64)
    if d.ndim != 2:
        raise ShapeError(f"d_stack must be (M attempts, K corners), got shape {d.shape}")
    if not 1 <= n <= d.shape[0]:
        raise InputError(f"n must be between 1 and the {d.shape[0]} attempts, got {n}")
    rng = np.random.default_rng(seed)
    picks = np.argsort(rng.random((trials, d.shape[0])), axis=1)[:, :n]  # (trials, n)
    vals = d[picks]  # (trials, n, K)
    cnt = np.isfinite(vals).sum(axis=1)
    tot = np.where(np.isfinite(vals), vals, 0.0).sum(axis=1)
    return np.asarray(np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan))


@dataclass(frozen=True)
class FlatSceneScale:
    """Result of the flat-scene method (§3.5.2): homography, residual distortion, W-T scale."""

    #: (3, 3) float64. H mapping rectified tele pixels onto rectified wide pixels (RANSAC, cv2).
    homography: Array
    #: (k,) float64. Residual radial distortion of the tele after H: Δ(u) = u·Σ a_j ρ^(2j), ρ =
    #: |u|/r_ref, u = q_tele − c, pixels.
    radial_coeffs: Array
    #: Radius normalising ρ (the largest |u|), pixels.
    r_ref_px: float
    #: ``rms_h_px``, ``rms_residual_px``: RMS of q_wide − H(q_tele) before and after the
    #: residual-distortion fit (inliers).
    rms_h_px: float
    #: See ``rms_h_px`` above.
    rms_residual_px: float
    #: The W-T scale fitted on the tele points corrected for residual distortion only.
    wt: WTScale
    #: Homography inliers.
    inliers: int
    ok: bool = True
    reason: str = ""

    def undistort_tele(self, q_tele_rect: Any) -> Array:
        """Tele pixels (..., 2) corrected for the residual radial distortion (no homography)."""
        q = as_points(q_tele_rect, 2, "q_tele_rect")
        u = q - self.wt.center_px
        rho2 = np.sum(u**2, axis=-1, keepdims=True) / self.r_ref_px**2
        poly = sum(a * rho2 ** (j + 1) for j, a in enumerate(self.radial_coeffs))
        return np.asarray(q + u * poly)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "homography": np.asarray(self.homography).tolist(),
            "radial_coeffs": [float(a) for a in self.radial_coeffs],
            "r_ref_px": float(self.r_ref_px), "rms_h_px": float(self.rms_h_px),
            "rms_residual_px": float(self.rms_residual_px), "wt": self.wt.to_dict(),
            "inliers": int(self.inliers), "ok": self.ok, "reason": self.reason,
        }


def flat_scene_scale(
    q_wide_rect: Any,
    q_tele_rect: Any,
    center_px: Any,
    *,
    degree: int = 2,
    ransac_px: float = 1.0,
) -> FlatSceneScale:
    """W-T scale of a flat scene: homography → residual distortion → scale (thesis §3.5.2).

    1. H = ``cv2.findHomography(q_tele, q_wide, RANSAC)`` absorbs the plane's perspective;
    2. the residual r = q_wide − H(q_tele) is fitted (linear least squares, inliers) by a
       radial displacement of the tele about ``center_px``: r ≈ u·(a_0 + Σ_j a_j ρ^(2j)),
       j = 1..degree; a_0 is the part of the distortion H took as scale and is not applied;
    3. the tele points corrected for that residual distortion only (not warped by H) give the
       W-T scale and offset (:func:`~phonestereo.fixes.wt_scale.fit_wt_scale`).

    Only valid for a flat scene (one homography). Data that cannot give the fit returns
    ``ok=False`` with the reason.

    Parameters
    ----------
    q_wide_rect, q_tele_rect : array_like, shape (N, 2)
        Matched points, rectified (disparity along x), pixels.
    center_px : array_like, shape (2,)
        The tele principal point in the rectified frame.
    degree : int
        Number of even radial terms of the residual distortion (1–3).
    ransac_px : float
        RANSAC reprojection threshold of the homography, pixels.

    Examples
    --------
    A flat chart 12 px of disparity away, tele scaled by 1 − 8·10⁻⁴ and bent by a small
    residual distortion: the scale is recovered.

    >>> g = np.stack(np.meshgrid(np.linspace(300, 700, 15), np.linspace(250, 750, 15)), -1)
    >>> qw = g.reshape(-1, 2); c = np.array([500.0, 500.0])
    >>> u = (qw - [12.0, 0.0]) - c
    >>> qt = c + (1 - 8e-4) * u * (1 + 2e-4 * np.sum(u**2, 1, keepdims=True) / 300.0**2)
    >>> res = flat_scene_scale(qw, qt, c)
    >>> round(res.wt.scale, 5), res.ok
    (1.0008, True)
    """
    qw = as_points(q_wide_rect, 2, "q_wide_rect").reshape(-1, 2)
    qt = as_points(q_tele_rect, 2, "q_tele_rect").reshape(-1, 2)
    if qw.shape != qt.shape:
        raise ShapeError(f"q_wide_rect and q_tele_rect must pair up, got {qw.shape}, {qt.shape}")
    if not 1 <= degree <= 3:
        raise InputError(f"degree must be 1, 2 or 3 radial terms, got {degree}")
    c = np.asarray(center_px, dtype=np.float64).reshape(2)
    ok = np.isfinite(qw).all(1) & np.isfinite(qt).all(1)
    qw, qt = qw[ok], qt[ok]
    if len(qw) < max(MIN_POINTS, degree + 5):
        wt = fit_wt_scale(qw, qt, c)
        return FlatSceneScale(np.eye(3), np.zeros(degree), 1.0, np.nan, np.nan, wt, 0, False,
                              f"{len(qw)} matches; the flat-scene method needs >= "
                              f"{max(MIN_POINTS, degree + 5)}")
    H, mask = cv2.findHomography(qt, qw, cv2.RANSAC, ransac_px)
    if H is None:
        wt = fit_wt_scale(qw, qt, c)
        return FlatSceneScale(np.eye(3), np.zeros(degree), 1.0, np.nan, np.nan, wt, 0, False,
                              "no homography between the tele and wide points (not a flat "
                              "scene, or degenerate points)")
    inl = mask.reshape(-1).astype(bool)
    u = qt - c
    r_ref = float(np.max(np.linalg.norm(u, axis=1))) or 1.0
    rho2 = np.sum(u**2, axis=1) / r_ref**2
    # ρ⁰ column: the scale H took from the distortion's mean; fitted, then left out (step 3)
    cols = [u] + [u * rho2[:, None] ** (j + 1) for j in range(degree)]  # (N, 2) each
    A = np.stack([col.reshape(-1) for col in cols], axis=1)  # (2N, 1 + degree): x0, y0, x1...
    rows = np.repeat(inl, 2)
    coeffs, rms_h, rms_res = np.zeros(degree), np.nan, np.nan
    for it in range(FLAT_ITERATIONS):  # H also takes some of the radial term: alternate
        corrected = qt + u * sum(a * rho2[:, None] ** (j + 1) for j, a in enumerate(coeffs))
        if it:
            H, _ = cv2.findHomography(corrected[inl], qw[inl], 0)
        mapped = cv2.perspectiveTransform(corrected.reshape(-1, 1, 2), H).reshape(-1, 2)
        b = (qw - mapped).reshape(-1)
        sol, *_ = np.linalg.lstsq(A[rows], b[rows], rcond=None)
        coeffs = coeffs + sol[1:]
        rms_res = float(np.sqrt(np.mean((b[rows] - A[rows] @ sol) ** 2)))
        rms_h = float(np.sqrt(np.mean(b[rows] ** 2))) if it == 0 else rms_h
    corrected = qt + u * sum(a * rho2[:, None] ** (j + 1) for j, a in enumerate(coeffs))
    wt = fit_wt_scale(qw, corrected, c)
    return FlatSceneScale(
        np.asarray(H, dtype=np.float64), np.asarray(coeffs), r_ref, rms_h, rms_res, wt,
        int(inl.sum()), wt.ok, wt.reason,
    )


__all__ = [
    "FOCUS_FAIL_RELATIVE",
    "FlatSceneScale",
    "FocusVerdict",
    "average_disparities",
    "averaging_trials",
    "cluster_disparities",
    "detect_focus_failures",
    "flat_scene_scale",
    "sharpness",
]
