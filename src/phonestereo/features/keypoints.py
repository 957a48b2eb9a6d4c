"""Keypoints for window matching (thesis §1.2.1): DoG extrema with Hessian edge rejection.

"Our feature extractor uses difference of Gaussians […] to approximate Laplacian of Gaussian,
and its local extrema points to mark feature points. It then uses the hessian matrix in order to
disqualify 1D features and features that are not significant enough." The keypoint is the
integer pixel of the extremum: it is the centre of the left window, which is never resampled,
and the disparity is measured there (the DoG's own sub-pixel position would add nothing).
SIFT (OpenCV) is the alternative detector; its keypoints are rounded the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

DETECTORS = ("dog", "sift")


@dataclass(frozen=True, eq=False)
class Keypoints:
    """Integer-pixel keypoints, strongest first (or in :func:`detect_dog`'s priority order)."""

    #: ndarray, shape (N, 2), float64. (x, y) pixels (integers stored as float).
    xy: F64
    #: ndarray, shape (N,). |DoG| at the extremum (DN), or the SIFT response.
    response: F64

    def __len__(self) -> int:
        return len(self.xy)


def dog_noise_gain(sigma: float, k: float) -> float:
    """σ of the DoG response to unit white noise: ‖G_σ − G_kσ‖₂ (continuous approximation).

    >>> round(dog_noise_gain(1.0, 1.6), 3)
    0.146
    """
    s1, s2 = float(sigma) ** 2, (float(sigma) * float(k)) ** 2
    return float(np.sqrt(1 / (4 * np.pi * s1) + 1 / (4 * np.pi * s2) - 2 / (2 * np.pi * (s1 + s2))))


def _select(
    xs: NDArray[np.intp],
    ys: NDArray[np.intp],
    resp: F64,
    max_keypoints: int,
    cell: int,
    priority: bool = False,
) -> tuple[NDArray[np.intp], NDArray[np.intp], F64]:
    """At most ``max_keypoints``: the best of each cell × cell box go first. Returned strongest
    first, or (``priority``) in the order they were picked: the cells' best, strongest first,
    then the rest, strongest first."""
    if len(resp) > 4 * max_keypoints:  # only the strongest can be picked
        top = np.argpartition(-resp, 4 * max_keypoints)[: 4 * max_keypoints]
        xs, ys, resp = xs[top], ys[top], resp[top]
    order = np.argsort(-resp, kind="stable")
    xs, ys, resp = xs[order], ys[order], resp[order]
    if len(xs) <= max_keypoints:
        return xs, ys, resp
    key = (ys // cell) * (int(xs.max()) // cell + 1) + xs // cell
    _, first = np.unique(key, return_index=True)  # strongest of each cell
    rank = np.ones(len(xs), bool)
    rank[first] = False
    pick = np.concatenate([np.sort(first), np.flatnonzero(rank)])[:max_keypoints]
    if not priority:
        pick = pick[np.argsort(-resp[pick], kind="stable")]
    return xs[pick], ys[pick], resp[pick]


def _hessian_ok(
    dog: F32, xs: NDArray[np.intp], ys: NDArray[np.intp], r: float
) -> NDArray[np.bool_]:
    """Lowe's test at the extrema: det(H) > 0 and tr(H)² / det(H) < (r + 1)² / r."""
    c = dog[ys, xs]
    dxx = dog[ys, xs + 1] + dog[ys, xs - 1] - 2 * c
    dyy = dog[ys + 1, xs] + dog[ys - 1, xs] - 2 * c
    dxy = 0.25 * (
        dog[ys + 1, xs + 1] - dog[ys + 1, xs - 1] - dog[ys - 1, xs + 1] + dog[ys - 1, xs - 1]
    )
    tr, det = dxx + dyy, dxx * dyy - dxy * dxy
    return np.asarray((det > 0) & (tr * tr * r < (r + 1) ** 2 * det), dtype=bool)


def detect_dog(
    image: F32,
    *,
    mask_box: tuple[int, int, int, int] | None = None,
    sigma: float = 1.0,
    k: float = 1.6,
    threshold: float = 1.0,
    edge_ratio: float = 10.0,
    max_keypoints: int = 2000,
    cell: int = 8,
    priority: bool = False,
) -> Keypoints:
    """DoG extrema with Hessian rejection of edge-like and weak responses.

    Parameters
    ----------
    image : ndarray, shape (H, W), float32
        Gray image, DN.
    mask_box : (x0, y0, x1, y1), optional
        Keep keypoints with x0 ≤ x < x1 and y0 ≤ y < y1 (e.g. the ROI shrunk by the window);
        default: the image minus a 1-px border.
    sigma, k : float
        DoG = G_σ ∗ I − G_kσ ∗ I, σ in px.
    threshold : float
        Minimum |DoG| at the extremum, DN (e.g. 5 × noise σ × :func:`dog_noise_gain`).
    edge_ratio : float
        Lowe's r: reject tr(H)² / det(H) ≥ (r + 1)² / r (an edge) and det(H) ≤ 0 (a saddle).
    max_keypoints : int
        Cap on the count; the strongest of every ``cell``² box is kept first, then the rest.
    cell : int
        Box size for spreading the keypoints, px.
    priority : bool
        Return them in the order they are picked (the strongest of every cell, strongest
        first, then the rest, strongest first) instead of strongest first. The first n of
        ``max_keypoints`` = N > n are the n that ``max_keypoints`` = n picks when the 4n
        strongest candidates already hold n cells; otherwise they are spread over more cells.

    Returns
    -------
    Keypoints

    Examples
    --------
    One Gaussian blob (σ = 2 px) at (30, 20), on a plain background:

    >>> yy, xx = np.mgrid[0:40, 0:60]
    >>> img = (50 + 100 * np.exp(-((xx - 30) ** 2 + (yy - 20) ** 2) / 8.0)).astype(np.float32)
    >>> detect_dog(img).xy.tolist()
    [[30.0, 20.0]]
    """
    if sigma <= 0 or k <= 1 or edge_ratio <= 1 or max_keypoints < 1:
        raise InputError(
            f"DoG needs sigma > 0, k > 1, edge_ratio > 1, max_keypoints >= 1; got {sigma=}, "
            f"{k=}, {edge_ratio=}, {max_keypoints=}"
        )
    img = np.asarray(image, np.float32)
    h, w = img.shape
    x0, y0, x1, y1 = mask_box if mask_box is not None else (1, 1, w - 1, h - 1)
    x0, y0, x1, y1 = max(x0, 1), max(y0, 1), min(x1, w - 1), min(y1, h - 1)
    if x1 <= x0 or y1 <= y0:
        return Keypoints(np.zeros((0, 2)), np.zeros(0))
    # the DoG of the box and a margin that holds the blur kernel: identical to the whole image's
    m = int(np.ceil(4 * sigma * k)) + 2
    ax, ay = max(x0 - m, 0), max(y0 - m, 0)
    sub = img[ay : min(y1 + m, h), ax : min(x1 + m, w)]
    dog = cv2.GaussianBlur(sub, (0, 0), sigma) - cv2.GaussianBlur(sub, (0, 0), sigma * k)
    box = np.ones((3, 3), np.uint8)
    win = (slice(y0 - ay, y1 - ay), slice(x0 - ax, x1 - ax))
    dw, thr = dog[win], float(threshold)
    ext = cv2.bitwise_or(  # 3 × 3 maximum or minimum, and |DoG| above the threshold
        cv2.compare(dw, cv2.dilate(dog, box)[win], cv2.CMP_EQ),
        cv2.compare(dw, cv2.erode(dog, box)[win], cv2.CMP_EQ),
    )
    strong = cv2.bitwise_or(cv2.compare(dw, thr, cv2.CMP_GT), cv2.compare(dw, -thr, cv2.CMP_LT))
    nz = cv2.findNonZero(cv2.bitwise_and(ext, strong))
    if nz is None:
        return Keypoints(np.zeros((0, 2)), np.zeros(0))
    xs = nz[:, 0, 0].astype(np.intp) + (x0 - ax)
    ys = nz[:, 0, 1].astype(np.intp) + (y0 - ay)
    resp = np.abs(dog[ys, xs]).astype(np.float64)
    want = 4 * max_keypoints  # _select picks among the strongest `want` that pass
    if len(resp) > 2 * want:  # test the strongest first; the rest only if too few pass
        top = np.argpartition(-resp, 2 * want)[: 2 * want]
        ok = _hessian_ok(dog, xs[top], ys[top], edge_ratio)
        if ok.sum() >= want:
            xs, ys, resp = xs[top[ok]], ys[top[ok]], resp[top[ok]]
        else:
            ok = _hessian_ok(dog, xs, ys, edge_ratio)
            xs, ys, resp = xs[ok], ys[ok], resp[ok]
    else:
        ok = _hessian_ok(dog, xs, ys, edge_ratio)
        xs, ys, resp = xs[ok], ys[ok], resp[ok]
    xs, ys, resp = _select(xs + ax, ys + ay, resp, max_keypoints, cell, priority)
    return Keypoints(np.stack([xs, ys], axis=1).astype(np.float64), resp)


def detect_sift(
    image: F32,
    *,
    mask_box: tuple[int, int, int, int] | None = None,
    max_keypoints: int = 2000,
) -> Keypoints:
    """OpenCV SIFT keypoints rounded to the nearest pixel (duplicates merged), strongest first.

    Parameters as :func:`detect_dog`. SIFT's own sub-pixel position and scale are not used:
    the window match measures the disparity at the pixel.
    """
    img = np.asarray(image, np.float32)
    h, w = img.shape
    x0, y0, x1, y1 = mask_box if mask_box is not None else (1, 1, w - 1, h - 1)
    mask = np.zeros((h, w), np.uint8)
    mask[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = 255
    u8 = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    kps = cv2.SIFT_create(nfeatures=int(max_keypoints)).detect(u8, mask)  # type: ignore[attr-defined]
    if not kps:
        return Keypoints(np.zeros((0, 2)), np.zeros(0))
    pts = np.rint(np.array([kp.pt for kp in kps])).astype(np.int64)
    resp = np.array([kp.response for kp in kps], np.float64)
    inside = (pts[:, 0] >= x0) & (pts[:, 0] < x1) & (pts[:, 1] >= y0) & (pts[:, 1] < y1)
    pts, resp = pts[inside], resp[inside]
    order = np.argsort(-resp, kind="stable")
    pts, resp = pts[order], resp[order]
    _, first = np.unique(pts[:, 1] * (w + 1) + pts[:, 0], return_index=True)
    first = np.sort(first)[:max_keypoints]
    return Keypoints(pts[first].astype(np.float64), resp[first])
