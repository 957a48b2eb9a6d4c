"""The non-disparity-axis fix in the flows (thesis §3.2): a learned residual radial distortion.

A factory describes a lens whose radial polynomial has odd terms with OpenCV's even-order model
(§3.2 reason 2); its distortion also moves with focus (reason 3). What is left after
rectification is a radial displacement δ(q) = P(r)·û, the same in e (its y part) as in d (its x
part), and it differs between the sensor positions where the faces were learned and where a
chart is measured, which the learned correction's smooth field does not carry
(docs/module-random.md, session 11).

**Its centre is the wide's principal point** (:func:`wide_center_px`). The factory fits each
lens over its own whole field, so the wide's even-order model is a compromise over angles up to
its corners and misses most where the tele looks, about its centre, while the tele's model is
fitted over those same central angles and misses little; in the rectified frame (the wide's
pixels) the tele's residual is smaller still by the zoom. Until session 19 P was centred on the
tele's principal point, 20–30 px away on the random modules: near the centre P rises steeply
(~0.3 % of r), so a misplaced centre moved the faces' and the chart's corrections apart, and on
random-3030 the fix added +0.7 % to every depth under every oracle; centred on the wide's
principal point the 65 kept sets' mean errors read 0.225 % in rms instead of 0.290 %
(docs/module-random.md, session 19).

The flows therefore, when ``FlowConfig.radial_residual`` is on:

- in the learning, fit P (:class:`~phonestereo.fixes.distortion.RadialResidualFix`, degree
  :data:`RADIAL_DEGREE`) to the non-disparity error e of each face capture's whole-view W-T
  matches (:func:`fit_capture_radial`) and correct that capture's face disparities by −δ_x;
- in the application, correct the ROI's matches (d and e) by the fit pooled over the learning
  captures (:func:`pool_radial`: the median curve) before the ROI's own W-T scale is fitted
  (:func:`correct_matches`), and refer the learned faces to that same pooled fit
  (:func:`refer_to_pooled_radial`).

Beyond the largest learned radius P is held at its value there (a polynomial is not
extrapolated).

Examples
--------
Two captures see the same residual, 0.3·(r/500)² px, through e:

>>> rng = np.random.default_rng(1)
>>> q = rng.uniform(0.0, 1000.0, size=(400, 2))
>>> r, u = radial_geometry(q, (500.0, 500.0))
>>> fits = [fit_capture_radial(q, u[:, 1] * 0.3 * (r / 500.0) ** 2 + rng.normal(0, 0.01, 400),
...                            (500.0, 500.0)) for _ in range(2)]
>>> pooled = pool_radial(fits)
>>> round(float(pooled.radial(500.0)), 2)
0.3
>>> d, e = correct_matches(pooled, [[1000.0, 500.0]], [10.0], [0.0])
>>> round(float(d[0]), 2), round(float(e[0]), 2)     # δ at r = 500 px along +x
(9.7, 0.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.fixes.distortion import RadialResidualFix, radial_geometry
from phonestereo.geometry.checks import as_points
from phonestereo.rectification import Rectification

#: n of P(r): a cubic follows an odd lens's residual over the tele's field (degree 4 chased the
#: e noise of one capture's matches on the random modules; 2 left a third of the residual).
RADIAL_DEGREE = 3
#: Fewest finite matches for one capture's fit (its e scatters ~0.1 px per match).
MIN_MATCHES = 50


def wide_center_px(rect: Rectification) -> tuple[float, float]:
    """The centre of the residual radial distortion: the wide's principal point in ``rect``'s
    rectified frame, px (module docstring).

    Examples
    --------
    A ×3 tele 12 mm along −y, turned 0.5° about x (the rectified frame turns with the baseline,
    so the principal point moves):

    >>> from phonestereo.geometry import Camera, Rig, Transform
    >>> cam = Camera.from_matrix((1000, 750), [[800, 0, 505], [0, 800, 370], [0, 0, 1]])
    >>> T = Transform.from_rotvec([np.deg2rad(0.5), 0, 0], [0, -0.012, 0])
    >>> rect = Rectification.from_rig(Rig(cam, cam.scaled(3.0), T), "canonical")
    >>> c = wide_center_px(rect)
    >>> bool(np.allclose(rect.unrectify_wide([c]), [[505, 370]]))
    True
    """
    pp = np.asarray(rect.rig.wide.K, dtype=np.float64)[:2, 2]
    c = np.asarray(rect.points_wide(pp[None, :]), dtype=np.float64).reshape(2)
    return float(c[0]), float(c[1])


def fit_capture_radial(
    xy: Any, e: Any, center: Any, *, degree: int = RADIAL_DEGREE
) -> RadialResidualFix | None:
    """P(r) of one capture from its matches' non-disparity error, or None when the matches are
    too few or the fit does not lower the spread of e.

    Parameters
    ----------
    xy : array_like, shape (N, 2)
        Rectified wide pixels of the matches (after the W-T scale).
    e : array_like, shape (N,)
        Their non-disparity error, px.
    center : (x, y)
        The radial centre, rectified px: the wide's principal point (:func:`wide_center_px`).
    degree : int
        n of P.
    """
    q = as_points(xy, 2, "xy").reshape(-1, 2)
    ev = np.asarray(e, dtype=np.float64).reshape(-1)
    ok = np.isfinite(q).all(axis=1) & np.isfinite(ev)
    if ok.sum() < MIN_MATCHES:
        return None
    try:
        fit = RadialResidualFix.fit(q[ok], ev[ok], center, degree=degree)
    except InputError:
        return None
    return fit if fit.rms_after_px < fit.rms_before_px else None


def pool_radial(
    fits: Sequence[RadialResidualFix | None], *, degree: int = RADIAL_DEGREE, samples: int = 64
) -> RadialResidualFix | None:
    """The captures' fits pooled: the median of their P(r) over a radius grid up to the smallest
    fitted radius, fitted again by P of ``degree`` (no offset: the ROI fits its own). None
    without a fit. Its ``rms_before_px`` / ``rms_after_px`` are the median curve's spread and
    the refit's residual; ``n_used`` / ``n_total`` count the captures."""
    good = [f for f in fits if f is not None]
    if not good:
        return None
    rho = min(f.radius_scale_px for f in good)
    r = np.linspace(0.0, rho, samples)
    curve = np.median(np.stack([f.radial(r) for f in good]), axis=0)
    A = np.stack([(r / rho) ** k for k in range(1, degree + 1)], axis=1)
    coef = np.linalg.lstsq(A, curve, rcond=None)[0]
    res = A @ coef - curve
    return RadialResidualFix(
        good[0].center_px, 0.0, tuple(float(a) for a in coef), float(rho),
        float(np.std(curve)), float(np.sqrt(np.mean(res**2))), len(good), len(fits),
    )


def radial_shift(fix: RadialResidualFix, xy: Any) -> Any:
    """δ(q) = P(min(r, ρ))·û at rectified pixels (N, 2) → (N, 2), px: its x part is what a
    disparity carries, its y part what e carries."""
    q = as_points(xy, 2, "xy").reshape(-1, 2)
    r, u = radial_geometry(q, fix.center_px)
    return fix.radial(np.minimum(r, fix.radius_scale_px))[:, None] * u


def correct_matches(fix: RadialResidualFix, xy: Any, d: Any, e: Any) -> tuple[Any, Any]:
    """(d, e) of rectified matches less δ(q) (:func:`radial_shift`), px (N,) each."""
    delta = radial_shift(fix, xy)
    dv = np.asarray(d, dtype=np.float64).reshape(-1) - delta[:, 0]
    ev = np.asarray(e, dtype=np.float64).reshape(-1) - delta[:, 1]
    return dv, ev


def refer_to_pooled_radial(obs: np.ndarray, pooled: RadialResidualFix | None) -> np.ndarray:
    """Observations whose disparity had their own capture's radial fit taken out (finite
    ``radial_px``) with the pooled fit's taken out instead (thesis §3.2), in place.

    The application takes the pooled fit out of a ROI, so the faces must carry the same one:
    one capture's cubic, fitted to the e of its 100–700 matches, moved its faces by up to
    0.23 px, and the learned correction carried that to every chart. Over the 28 bench sets
    the sets' mean errors' rms falls 0.386 → 0.304 % (random modules) and 0.232 → 0.180 %
    (``folded-x3`` 0–7); random-1004 +1.07 → +0.14 % (docs/module-random.md, session 14).
    Observations without ``radial_px`` (stores before schema 5) are left as learned.
    ``obs`` is a structured observation array
    (:func:`~phonestereo.learning.observation.as_observation_array`).
    """
    if pooled is None or obs.size == 0:
        return obs
    own = obs["radial_px"]
    ok = np.isfinite(own)
    if ok.any():
        q = np.column_stack([obs["x_px"][ok], obs["y_px"][ok]])
        new = radial_shift(pooled, q)[:, 0]
        obs["d_measured_px"][ok] += own[ok] - new
        obs["radial_px"][ok] = new
    return obs


def radial_from_dict(data: dict[str, Any]) -> RadialResidualFix:
    """The inverse of :meth:`RadialResidualFix.to_dict` (the fix store keeps it as JSON)."""
    return RadialResidualFix(
        (float(data["center_px"][0]), float(data["center_px"][1])), float(data["offset_px"]),
        tuple(float(a) for a in data["coefficients"]), float(data["radius_scale_px"]),
        float(data["rms_before_px"]), float(data["rms_after_px"]), int(data["n_used"]),
        int(data["n_total"]),
    )


__all__ = [
    "MIN_MATCHES",
    "RADIAL_DEGREE",
    "correct_matches",
    "fit_capture_radial",
    "pool_radial",
    "radial_from_dict",
    "radial_shift",
    "refer_to_pooled_radial",
    "wide_center_px",
]
