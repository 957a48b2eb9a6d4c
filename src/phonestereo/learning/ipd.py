"""The IPD model: faces as a ruler (thesis §3.6, eq. 10 and 11 of docs/equations.md).

**Depth from IPD** (eq. 11): ``Z = f · IPD · cos(yaw) / ipd_px`` (:func:`depth_from_ipd`;
1 mm of IPD error is 1.6 % of depth); :func:`face_depth` does it exactly on undistorted rays,
for a yaw measured from the line of sight (a real head, as landmarks see it) or the image plane.

**Face-chart mode** (known IPD, thesis §2.2): all faces are printed flat on one plane, so the
yaw of each face is the chart's tilt — not the yaw its landmarks report, which is the
photographed head's. :func:`fit_face_plane` finds the plane (depth and tilt) that gives every
face its known IPD, and reads each face's depth off it.

**Population mode** (real faces of unknown IPD): :class:`IpdPrior` holds the sex-specific
priors of §3.6 (male 65 ± 3.6 mm, female 60 ± 3.5 mm) or Dodgson's adult mean 63 mm. The mean
of n independent IPDs is within ``ε`` of the population mean with probability ≥ 1 − α once n
reaches :func:`samples_needed` (eq. 10, Chebyshev, or its normal counterpart);
:func:`population_scale` turns n stereo-measured IPDs into a depth-scale correction and bound.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.stats import norm

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry import Camera

F64 = NDArray[np.float64]
#: Population-mean adult IPD (Dodgson 2004) and the face chart's printed IPD, metres.
IPD_M = 0.063
Bound = Literal["chebyshev", "normal"]


def depth_from_ipd(ipd_px: Any, f_px: float, ipd_m: Any = IPD_M, yaw_rad: Any = 0.0) -> F64:
    """Z = f · IPD · cos(yaw) / ipd_px (eq. 11), metres; broadcasts.

    Parameters
    ----------
    ipd_px : array_like
        Pupil-to-pupil distance in the image, pixels (> 0; otherwise NaN).
    f_px : float
        Focal length, pixels.
    ipd_m : array_like
        True IPD, metres.
    yaw_rad : array_like
        Head yaw out of the image plane (foreshortens ``ipd_px`` by cos(yaw)).

    Examples
    --------
    >>> float(depth_from_ipd(47.25, 1500.0))                         # 63 mm at 2 m
    2.0
    >>> round(float(depth_from_ipd(47.25, 1500.0, 0.064)) / 2 - 1, 4) # 1 mm IPD error: 1.6 %
    0.0159
    >>> round(float(depth_from_ipd(47.25 * np.cos(0.3), 1500.0, yaw_rad=0.3)), 9)
    2.0
    """
    if not np.isfinite(f_px) or f_px <= 0:
        raise InputError(f"f_px must be a positive focal length in pixels, got {f_px}")
    ipd = np.asarray(ipd_px, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = f_px * np.asarray(ipd_m, dtype=np.float64) * np.cos(yaw_rad) / ipd
    return np.where(ipd > 0, z, np.nan)


def _rays(pupils_px: Any, camera: Camera) -> F64:
    """Undistorted rays (..., 2, 3), z = 1, of pupils (..., 2, 2)."""
    p = np.asarray(pupils_px, dtype=np.float64)
    if p.ndim < 2 or p.shape[-2:] != (2, 2):
        raise ShapeError(f"pupils_px must have shape (..., 2, 2) (face, eye, xy), got {p.shape}")
    return np.asarray(camera.unproject(p))


def _depth_along(r0: F64, r1: F64, axis: F64, ipd_m: Any) -> tuple[F64, F64]:
    """Midpoint depth (...,) and midpoint (..., 3) of a segment of length ``ipd_m`` along unit
    ``axis`` (..., 3) from ray ``r0`` to ray ``r1`` (..., 3, z = 1): least squares of
    s0·r0 + L·a = s1·r1."""
    A = np.stack([r0, -r1], axis=-1)  # (..., 3, 2)
    b = -np.asarray(ipd_m, dtype=np.float64)[..., None] * axis
    AtA = np.einsum("...ki,...kj->...ij", A, A)
    Atb = np.einsum("...ki,...k->...i", A, b)
    s = np.linalg.solve(AtA, Atb[..., None])[..., 0]
    mid = 0.5 * (s[..., 0, None] * r0 + s[..., 1, None] * r1)
    return np.asarray(mid[..., 2]), np.asarray(mid)


def _unit(v: F64) -> F64:
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True))


def _eye_axis(r0: F64, r1: F64, w: F64, yaw: F64) -> F64:
    """Unit eye axis (..., 3) from ray r0 towards ray r1 whose angle out of the plane
    perpendicular to ``w`` is ``yaw``: it must lie in the plane of the two rays (the pupils are
    on them), so a = cos·u1 + β·u2 with u1 ⟂ w in that plane and β = sin(yaw) / (u2 · w).
    NaN when no such axis exists (|β| > 1)."""
    n = np.cross(r0, r1)
    u1 = _unit(np.cross(n, w))
    u1 = u1 * np.sign(np.sum(u1 * (r1 - r0), axis=-1, keepdims=True))
    u2 = _unit(np.cross(n, u1))
    u2 = u2 * np.sign(np.sum(u2 * w, axis=-1, keepdims=True))
    with np.errstate(divide="ignore", invalid="ignore"):
        beta = np.sin(yaw) / np.sum(u2 * w, axis=-1, keepdims=True)
        return np.asarray(np.sqrt(1.0 - beta**2) * u1 + beta * u2)


def face_depth(
    pupils_px: Any,
    camera: Camera,
    ipd_m: Any = IPD_M,
    yaw_rad: Any = 0.0,
    relative_to: Literal["sight", "image"] = "sight",
) -> F64:
    """Depth Z (...,) in metres of the pupil midpoint of faces, exactly, on undistorted rays.

    Parameters
    ----------
    pupils_px : array_like, shape (..., 2, 2)
        Pupils (x, y) per face, image-left eye first, pixels (distorted, as in the image).
    camera : Camera
        The camera that took the image (its lens model undistorts the pupils).
    ipd_m : array_like, shape (...)
        True IPD per face, metres.
    yaw_rad : array_like, shape (...)
        Yaw of the eye axis, positive when the image-right eye is farther.
    relative_to : {"sight", "image"}
        ``"sight"``: yaw from the plane perpendicular to the line of sight to the face — what
        landmarks measure, and 0 for a person looking at the camera. ``"image"``: yaw from the
        image plane (0: a print parallel to the sensor).

    Examples
    --------
    A frontal face 2 m in front of a 1500-px camera, eyes 63 mm apart:

    >>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> q = cam.project([[-0.0315, 0.0, 2.0], [0.0315, 0.0, 2.0]])
    >>> round(float(face_depth(q, cam, relative_to="image")), 9)
    2.0
    """
    rays = _rays(pupils_px, camera)
    r0, r1 = rays[..., 0, :], rays[..., 1, :]
    yaw = np.asarray(yaw_rad, dtype=np.float64)[..., None]
    if relative_to == "image":
        z_axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), r0.shape)
        return _depth_along(r0, r1, _eye_axis(r0, r1, z_axis, yaw), ipd_m)[0]
    if relative_to != "sight":
        raise InputError(f"relative_to must be 'sight' or 'image', got {relative_to!r}")
    los = _unit(_unit(r0) + _unit(r1))  # start: the bisector; then the midpoint's direction
    for _ in range(4):  # the correction is second order in yaw: converges in 2–3 steps
        z, mid = _depth_along(r0, r1, _eye_axis(r0, r1, los, yaw), ipd_m)
        los = _unit(mid)
    return z


@dataclass(frozen=True, eq=False)
class PlaneFit:
    """Faces of known IPD on one plane Z = c + gx·X + gy·Y (camera frame, metres).

    ``depth_m`` (N,): each face's pupil-midpoint depth on the plane; ``ipd_ratio`` (N,): its
    pupil distance on the plane / its known IPD; ``gradient``: (gx, gy) = (dZ/dX, dZ/dY), the
    chart's tilt; ``inliers`` (N,): faces within 3 · sigma_rel of their IPD; ``reason``: empty
    when at least 2 faces were fitted, else what limited the fit.
    """

    depth_m: F64
    ipd_ratio: F64
    gradient: tuple[float, float]
    inliers: NDArray[np.bool_]
    reason: str = ""

    @property
    def tilt_rad(self) -> float:
        """Angle between the plane's normal and the optical axis."""
        return float(np.arctan(np.hypot(*self.gradient)))


def fit_face_plane(
    pupils_px: Any,
    camera: Camera,
    ipd_m: float = IPD_M,
    *,
    sigma_rel: float = 0.015,
    max_tilt_rad: float = float(np.deg2rad(30.0)),
) -> PlaneFit:
    """Face-chart mode: the plane on which every face has its printed IPD, and their depths.

    Each face's pupils are intersected with the plane Z = c + gx·X + gy·Y; (c, gx, gy)
    minimise the robust (soft-L1) sum of ``(|P1 − P0| / IPD − 1) / sigma_rel`` over faces,
    plus a weak prior ``g / tan(max_tilt_rad)`` that fixes the tilt a single row of faces
    cannot. This is the chart's yaw (and pitch) correction: a flat print's landmarks report
    the photographed head's yaw, not the print's.

    Parameters
    ----------
    pupils_px : array_like, shape (N, 2, 2)
        Pupils per face (image-left first), pixels.
    camera : Camera
        The camera of the image.
    ipd_m : float
        The chart's printed IPD (63 mm).
    sigma_rel, max_tilt_rad : float
        Relative IPD noise of one face (landmark noise), for weighting; scale of the prior.

    Examples
    --------
    A chart 1.5 m away turned by 10° about the vertical axis, faces across the image:

    >>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> t = np.deg2rad(10.0)
    >>> u = np.array([np.cos(t), 0.0, np.sin(t)])
    >>> mids = np.array([[x, y, 1.5 + x * np.tan(t)] for x in (-0.4, 0, 0.4) for y in (-0.2, 0.2)])
    >>> eyes = np.stack([mids - 0.0315 * u, mids + 0.0315 * u], axis=1)
    >>> fit = fit_face_plane(cam.project(eyes), cam)
    >>> np.allclose(fit.depth_m, mids[:, 2], rtol=1e-4), round(np.degrees(fit.tilt_rad), 1)
    (True, 10.0)
    """
    rays = _rays(pupils_px, camera)
    if rays.ndim != 3:
        raise ShapeError(f"pupils_px must have shape (N, 2, 2), got {np.shape(pupils_px)}")
    if len(rays) == 0:
        raise InputError("fit_face_plane needs at least one face; found none")
    r = rays[ok := np.isfinite(rays).all(axis=(1, 2))]
    if len(r) == 0:
        raise InputError("every face's pupils fall outside the camera's valid field")
    z0 = float(np.median(face_depth(pupils_px, camera, ipd_m, relative_to="image")[ok]))
    prior = np.tan(max_tilt_rad)

    def plane(p: F64) -> tuple[F64, F64]:
        s = p[0] / (1.0 - p[1] * r[..., 0] - p[2] * r[..., 1])  # ray scale = depth (z = 1)
        pts = s[..., None] * r
        return np.linalg.norm(pts[:, 1] - pts[:, 0], axis=-1) / ipd_m, s.mean(axis=1)

    def residuals(p: F64) -> F64:
        return np.concatenate([(plane(p)[0] - 1.0) / sigma_rel, p[1:] / prior])

    sol = least_squares(residuals, [z0, 0.0, 0.0], loss="soft_l1", f_scale=2.0, x_scale=[z0, 1, 1])
    ratio_ok, depth_ok = plane(sol.x)
    depth, ratio = np.full(len(rays), np.nan), np.full(len(rays), np.nan)
    depth[ok], ratio[ok] = depth_ok, ratio_ok
    inliers = np.abs(ratio - 1.0) <= 3 * sigma_rel
    reason = "" if len(r) >= 2 else "one face: tilt fixed at 0 by the prior (eq. 11 only)"
    return PlaneFit(depth, ratio, (float(sol.x[1]), float(sol.x[2])), inliers, reason)


@dataclass(frozen=True)
class IpdPrior:
    """A population's IPD: mixture components ``(weight, mean_m, sd_m)``.

    Examples
    --------
    >>> p = IpdPrior.population()                      # §3.6: half male, half female
    >>> round(p.mean_m * 1000, 2), round(p.sd_m * 1000, 2)
    (62.5, 4.34)
    >>> IpdPrior.face_chart().sd_m
    0.0
    """

    components: tuple[tuple[float, float, float], ...]
    name: str = "custom"

    def __post_init__(self) -> None:
        w, m, sd = np.array(self.components, dtype=np.float64).reshape(-1, 3).T
        if len(w) == 0 or (w < 0).any() or w.sum() <= 0 or (sd < 0).any():
            raise InputError(f"IPD prior needs (weight, mean_m, sd_m) >= 0, got {self.components}")
        if not ((0.03 < m) & (m < 0.1)).all():
            raise InputError(f"IPD prior means must be in metres (30–100 mm), got {m.tolist()}")

    def _arrays(self) -> tuple[F64, F64, F64]:
        w, m, sd = np.array(self.components, dtype=np.float64).reshape(-1, 3).T
        return w / w.sum(), m, sd

    @classmethod
    def face_chart(cls, ipd_m: float = IPD_M) -> IpdPrior:
        """Every face has exactly ``ipd_m`` (the printed chart)."""
        return cls(((1.0, ipd_m, 0.0),), "face-chart")

    @classmethod
    def population(cls, male_fraction: float = 0.5) -> IpdPrior:
        """Adults, thesis §3.6: male median 65 mm (sd 3.6), female 60 mm (sd 3.5)."""
        if not 0 <= male_fraction <= 1:
            raise InputError(f"male_fraction must be in [0, 1], got {male_fraction}")
        return cls(((male_fraction, 0.065, 0.0036), (1 - male_fraction, 0.060, 0.0035)), "sexes")

    @classmethod
    def dodgson(cls) -> IpdPrior:
        """Adults, Dodgson 2004: mean 63 mm; sd 4 mm puts ±3 sd at 51–75 mm, his range for
        the vast majority of adults."""
        return cls(((1.0, IPD_M, 0.004),), "dodgson")

    @property
    def mean_m(self) -> float:
        """Mixture mean, metres."""
        w, m, _ = self._arrays()
        return float(np.dot(w, m))

    @property
    def sd_m(self) -> float:
        """Mixture standard deviation (within + between components), metres."""
        w, m, sd = self._arrays()
        return float(np.sqrt(np.dot(w, sd**2 + (m - np.dot(w, m)) ** 2)))

    def sample(self, n: int, rng: np.random.Generator) -> F64:
        """``n`` IPDs (metres) drawn from the mixture."""
        w, m, sd = self._arrays()
        k = rng.choice(len(w), size=int(n), p=w)
        return np.asarray(m[k] + sd[k] * rng.standard_normal(int(n)))


def _check_bound(sigma: float, alpha: float, bound: str) -> float:
    if not 0 < alpha < 1:
        raise InputError(f"alpha (allowed failure probability) must be in (0, 1), got {alpha}")
    if not np.isfinite(sigma) or sigma < 0:
        raise InputError(f"sigma must be a standard deviation >= 0, got {sigma}")
    if bound == "chebyshev":
        return float(1.0 / np.sqrt(alpha))
    if bound == "normal":
        return float(norm.ppf(1 - alpha / 2))
    raise InputError(f"bound must be 'chebyshev' or 'normal', got {bound!r}")


def samples_needed(
    sigma: float, eps: float, alpha: float = 0.05, bound: Bound = "chebyshev"
) -> int:
    """Faces n so that the mean IPD is within ``eps`` of the truth with probability ≥ 1 − α.

    Eq. 10: Chebyshev n ≥ σ² / (α ε²) (any distribution); normal n ≥ (z₁₋α/₂ σ / ε)².
    ``sigma`` and ``eps`` in the same unit. (The thesis's "13 people" is σ²/ε² with σ = 3.6,
    ε = 1 mm, i.e. α = 1: no guarantee at all.)

    Examples
    --------
    Men (σ = 3.6 mm), mean within 1 mm (1.6 % depth) with 95 % probability:

    >>> samples_needed(3.6, 1.0, 0.05), samples_needed(3.6, 1.0, 0.05, "normal")
    (260, 50)
    """
    k = _check_bound(sigma, alpha, bound)
    if not np.isfinite(eps) or eps <= 0:
        raise InputError(f"eps must be a positive error, got {eps}")
    return max(1, int(np.ceil((k * sigma / eps) ** 2 - 1e-9)))


def error_bound(n: Any, sigma: float, alpha: float = 0.05, bound: Bound = "chebyshev") -> F64:
    """Half-width ε(n) that the mean of ``n`` samples stays within with probability ≥ 1 − α.

    Inverse of :func:`samples_needed`: σ / √(α n) (Chebyshev) or z₁₋α/₂ σ / √n (normal).

    >>> round(float(error_bound(50, 3.6, 0.05, "normal")), 3)
    0.998
    """
    k, nn = _check_bound(sigma, alpha, bound), np.asarray(n, dtype=np.float64)
    if (nn < 1).any():
        raise InputError("n must be >= 1")
    return np.asarray(k * sigma / np.sqrt(nn))


@dataclass(frozen=True)
class ScaleEstimate:
    """Population mode: the depth-scale correction learned from n faces.

    ``scale`` multiplies stereo depths (true ≈ scale · stereo); it is within ``bound_rel``
    (relative) of the truth with probability ≥ 1 − ``alpha`` (eq. 10)."""

    scale: float
    n: int
    bound_rel: float
    alpha: float
    bound: str

    def converged(self, eps_rel: float) -> bool:
        """True when the bound is within ``eps_rel`` (e.g. 0.01 for 1 % depth)."""
        return self.bound_rel <= eps_rel


def population_scale(
    ipd_stereo_m: Any, prior: IpdPrior, alpha: float = 0.05, bound: Bound = "normal"
) -> ScaleEstimate:
    """Depth-scale correction from the IPDs that stereo depth implies for n real faces.

    A face at stereo depth Z_s with pixel IPD ``ipd_px`` has ``IPD_s = ipd_px · Z_s / f``;
    if stereo depths are off by a common factor (Z = k · Z_s), then ``IPD = k · IPD_s`` and
    the population mean gives ``k = mean_prior / mean(IPD_s)``, within the prior's σ / √n.
    The bound covers sampling only: faces from a population whose mean IPD differs from the
    prior's (say, only men: 65 vs 62.5 mm) bias ``k`` by the ratio of the means.

    >>> rng = np.random.default_rng(1)
    >>> prior = IpdPrior.population()
    >>> est = population_scale(prior.sample(400, rng) / 1.1, prior)    # stereo 10 % short
    >>> round(est.scale, 2), est.n, round(est.bound_rel, 4)
    (1.1, 400, 0.0068)
    """
    v = np.asarray(ipd_stereo_m, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if len(v) == 0 or (v <= 0).any():
        raise InputError("population_scale needs >= 1 stereo IPD, all positive lengths in metres")
    eps = float(error_bound(len(v), prior.sd_m, alpha, bound)) / prior.mean_m
    return ScaleEstimate(prior.mean_m / float(v.mean()), len(v), eps, alpha, bound)
