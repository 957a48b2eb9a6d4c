"""The sparse matcher on phone-like images: JPEG, sharpening, denoising and ISP renders (#16).

Three measurements, each a function the tests call (tests/features/test_match_isp.py):

* :func:`degraded` — a real pair with ground truth (Middlebury-Q Adirondack and Piano,
  scikit-image's motorcycle) degraded as a phone would (both images JPEG q95 / q85 / q70; the
  right one sharpened 1.8·I − 0.8·Gauss(I, σ = 1 px); the right one denoised by
  cv2.fastNlMeansDenoisingColored h = 5 on the colour image, then grey), compared with the
  same scene's clean pair: matches, median |d − GT|, fraction within 0.5 px;
* :func:`isp_pair` / :func:`isp_honesty` — textured planes rendered as ``bench_match`` does,
  then each camera's radiance through the virtual module's phone ISP (``phonestereo.sim.isp``:
  Bayer raw with noise, demosaicing, tone curve, bilateral denoise, unsharp mask, JPEG) at the
  settings of :data:`ISP_SETTINGS`; the fraction of |d − d_true| ≤ σ_d;
* the table: ``python benchmarks/bench_match_isp.py`` prints both (its runner).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import cv2
import numpy as np

from _support import stereo_eval as bench
from phonestereo.features.matching import MatchConfig, match_rectified

SCENES = ("Adirondack", "Piano", "motorcycle")
CASES = ("clean", "jpeg95", "jpeg85", "jpeg70", "sharpened", "denoised")

#: ISP settings from mild to strong (the ``IspSpec`` fields that change; the rest default):
#: a main camera in good light, the default tuning, a small-pixel tele in dim light
ISP_SETTINGS: dict[str, dict[str, Any]] = {
    "mild": {"denoise_strength": 1.0, "sharpen_amount": 0.3, "jpeg_quality": 95},
    "default": {},
    "strong": {
        "denoise_strength": 3.0,
        "sharpen_amount": 1.2,
        "sharpen_radius_px": 1.2,
        "jpeg_quality": 85,
    },
}


def load_scene(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(left, right, GT disparity with NaN where unknown, ndisp) of a scene in :data:`SCENES`."""
    if name == "motorcycle":
        pair = bench.load_motorcycle()
        if pair is None:
            raise FileNotFoundError("scikit-image is not installed (motorcycle pair)")
        return pair
    return bench.load_middlebury(name)


def jpeg(img: np.ndarray, quality: int) -> np.ndarray:
    """``img`` encoded and decoded by OpenCV's JPEG at ``quality`` (1–100)."""
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    assert ok
    return np.asarray(cv2.imdecode(buf, cv2.IMREAD_UNCHANGED))


def sharpened(img: np.ndarray) -> np.ndarray:
    """The unsharp mask of issue #16: 1.8·I − 0.8·Gauss(I, σ = 1 px), rounded to 8 bits."""
    f = img.astype(np.float64)
    out = 1.8 * f - 0.8 * cv2.GaussianBlur(f, (0, 0), 1.0)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def right_colour(scene: str) -> np.ndarray:
    """The scene's right image in colour (BGR), as the file holds it."""
    if scene == "motorcycle":
        from skimage import data  # type: ignore[import-not-found, unused-ignore]

        rgb = np.asarray(data.stereo_motorcycle()[1])
        return np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    path = bench.DATA / f"middeval3_Q_{scene}" / "im1.png"
    return np.asarray(cv2.imread(str(path), cv2.IMREAD_COLOR))


def denoised(bgr: np.ndarray) -> np.ndarray:
    """The issue's denoiser: cv2.fastNlMeansDenoisingColored, h = hColor = 5, then grey."""
    out = cv2.fastNlMeansDenoisingColored(bgr, None, 5, 5)
    return np.asarray(cv2.cvtColor(out, cv2.COLOR_BGR2GRAY))


def degrade(
    left: np.ndarray, right: np.ndarray, case: str, scene: str = ""
) -> tuple[np.ndarray, np.ndarray]:
    """The grey pair of ``case`` (one of :data:`CASES`); "denoised" needs the ``scene`` name
    (the colour right image is denoised, as the issue did)."""
    if case.startswith("jpeg"):
        q = int(case[4:])
        return jpeg(left, q), jpeg(right, q)
    if case == "sharpened":
        return left, sharpened(right)
    if case == "denoised":
        return left, denoised(right_colour(scene))
    return left, right


def degraded(scene: str, case: str, cfg: MatchConfig | None = None) -> dict[str, Any]:
    """Matches, median |d − GT| and fraction within 0.5 px of ``scene`` under ``case``."""
    left, right, gt, ndisp = load_scene(scene)
    a, b = degrade(left, right, case, scene)
    res = match_rectified(a, b, max_disparity=ndisp, config=cfg)
    g = bench.gt_at(gt, res.xy)
    ok = np.isfinite(g)
    err = np.abs(res.d - g)[ok]
    return {
        "scene": scene,
        "case": case,
        "matches": len(res),
        "median_abs_err_px": float(np.median(err)) if len(err) else float("nan"),
        "within_0.5px": float(np.mean(err <= 0.5)) if len(err) else float("nan"),
        "within_1_sigma": float(np.mean(err <= res.sigma_d[ok])) if len(err) else float("nan"),
        "seconds": res.seconds,
    }


def isp_pair(
    planes: list[tuple[float, tuple[float, float, float], tuple[float, float]]],
    setting: dict[str, Any],
    size: tuple[int, int] = (320, 240),
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A rendered rectified pair through the phone ISP (grey JPEG luma) and the true disparity.

    The scene and cameras are ``bench_match.render_pair``'s (f = 600 px, B = 2 cm, texel 5 px);
    each view's radiance goes through :func:`phonestereo.sim.isp.isp_file` with
    ``IspSpec(**setting)`` and is decoded as the pipeline reads it (JPEG luma).
    """
    from phonestereo.sim.isp import IspSpec, gray_of_file, isp_file
    from phonestereo.sim.render import render_view
    from phonestereo.sim.sensor import SensorModel

    scene, cam, poses, d_true = bench_scene(planes, size, seed)
    isp, sensor = IspSpec(**setting), SensorModel()
    rng = np.random.default_rng(seed + 1000)
    out = []
    for pose in poses:
        view = render_view(cam, pose, scene)
        out.append(gray_of_file(isp_file(view.radiance, isp, sensor, rng)[0]))
    return out[0], out[1], d_true


def bench_scene(
    planes: list[tuple[float, tuple[float, float, float], tuple[float, float]]],
    size: tuple[int, int],
    seed: int,
    f_px: float = 600.0,
    baseline_m: float = 0.02,
    texel_px: float = 5.0,
) -> tuple[Any, Any, tuple[Any, Any], np.ndarray]:
    """Scene, camera, (left, right) poses and true left disparity of ``bench_match.render_pair``."""
    from phonestereo.charts.texture import TexturedPlane
    from phonestereo.geometry import Camera, Transform
    from phonestereo.sim.render import render_view
    from phonestereo.sim.scene import PlanarObject, Scene, facing_pose

    w, h = size
    cam = Camera(size, f_px, f_px, (w - 1) / 2, (h - 1) / 2)
    objs = []
    for k, (d, tilt, centre) in enumerate(planes):
        z = f_px * baseline_m / d
        plane = TexturedPlane(
            (2.5 * w * z / f_px, 2.5 * h * z / f_px), seed=seed + k, feature_m=texel_px * z / f_px
        )
        pose = facing_pose(plane.size_m, z, tilt_rad=tilt, center_m=centre)
        objs.append(PlanarObject(plane, pose, name=f"plane{k}"))
    scene = Scene(tuple(objs))
    poses = (Transform.identity(), Transform(np.eye(3), np.array([-baseline_m, 0.0, 0.0])))
    depth = render_view(cam, poses[0], scene).depth_m.astype(np.float64)
    return scene, cam, poses, f_px * baseline_m / depth


@lru_cache(maxsize=16)
def isp_honesty(setting: str, tilt: tuple[float, float, float], seed: int = 0) -> dict[str, Any]:
    """Matches, median |d − d_true|, the fraction within σ_d on one ISP-rendered plane, and the
    left→right / right→left statistic of the phone pairs (``match_phone.both_directions``) on
    the same pair: its RMS z and the correlation of the two directions' errors against the truth.
    """
    from _support.match_phone import both_directions

    left, right, d_true = isp_pair([(16.3, tilt, (0.0, 0.0))], ISP_SETTINGS[setting], seed=seed)
    res, rl, i, j = both_directions(
        np.asarray(left, np.float64), np.asarray(right, np.float64), max_disparity=32
    )
    xi = np.rint(res.xy).astype(int)
    truth = d_true[xi[:, 1], xi[:, 0]]
    signed = res.d - truth
    err = np.abs(signed)
    z = (res.d[i] - rl.d[j]) / np.hypot(res.sigma_d[i], rl.sigma_d[j])
    corr = np.corrcoef(signed[i], rl.d[j] - truth[i])[0, 1] if len(i) > 2 else np.nan
    return {
        "setting": setting,
        "tilt": tilt,
        "matches": len(res),
        "median_err_px": float(np.median(signed)) if len(err) else float("nan"),
        "median_abs_err_px": float(np.median(err)) if len(err) else float("nan"),
        "within_1_sigma": float(np.mean(err <= res.sigma_d)) if len(err) else float("nan"),
        "median_sigma_d_px": float(np.median(res.sigma_d)) if len(err) else float("nan"),
        "lr_paired": len(i),
        "lr_rms_z": float(np.sqrt(np.mean(z**2))) if len(z) else float("nan"),
        "lr_error_corr": float(corr),
    }
