"""Calibration on rendered charts: render, detect with the shipped detector, solve, z-scores.

Imported by ``tests/calibration/test_calib_sim.py`` and ``benchmarks/bench_calibrate_sim.py``
(as ``_support.calib_sim``; ``tests/conftest.py`` puts ``tests/`` on ``sys.path``, the
benchmark inserts it itself). What it does:

- :func:`detect_board`: a complete plain chessboard in an image → corners and row-major ids,
  by ``features.chessboard.find_chessboard`` — the detector ``phonestereo calibrate`` uses
  (OpenCV finds and orders the board, the shared saddle fit refines every corner in a window
  of 0.35 of the corner spacing, at most 6 px), so the covariance figures describe the
  product's path.
- :func:`detect_three_plane`: the three boards of the three-plane chart, largest first, each
  painted out once found, labelled with the chart's ids.
- :func:`sim_views`: every capture of a rendered ``calibration`` set → wide and tele
  :class:`BoardView` lists (None where no complete board was found).
- :func:`true_parameters`: the ground-truth parameter vector in the calibration layout, for
  z-scores (ground truth is read only here and in the tests, which are evaluation code).
- :func:`render_set`, :func:`evaluate_seed`, :func:`z_summary`: render one seed of the
  scenario, calibrate it (``radial-odd`` with the true 4 radial terms; ``opencv5`` beside it)
  and summarise the z-scores over seeds.
- :func:`iid_reference_views`: the same corners moved to their true projections plus iid
  Gaussian noise at the solve's own σ — on them the covariance is exact by construction, so
  their z-scores are the reference for what the rendered ones can reach.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from phonestereo.calibration.bundle import Layout, Observations, residuals_and_jacobian
from phonestereo.calibration.result import CalibrationResult
from phonestereo.calibration.solve import CalibrationOptions, calibrate_stereo
from phonestereo.calibration.views import BoardView, chessboard_object_points
from phonestereo.charts.three_plane import ThreePlaneChart
from phonestereo.features.chessboard import find_chessboard
from phonestereo.geometry import Transform
from phonestereo.io import load_capture_set, read_gray
from phonestereo.sim.calib_scenario import CalibrationConfig
from phonestereo.sim.ground_truth import GroundTruth, load_ground_truth
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import plan_scenario
from phonestereo.sim.writer import write_capture_set


def detect_board(
    image: np.ndarray, pattern: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray] | None:
    """Corners (N, 2) and row-major ids (N,) of a complete chessboard, or None if not found.

    The shipped detector (``find_chessboard``); corners whose saddle fit fails are dropped
    (their ids with them).
    """
    det = find_chessboard(image, pattern)
    return (det.points, det.ids) if det.found else None


def detect_three_plane(
    image: np.ndarray, chart: ThreePlaneChart, name: str = ""
) -> BoardView | None:
    """Labelled corners of every board of the three-plane chart found in the image, or None.

    The boards differ in size; the largest is searched first and painted out (its outline
    grown by 1.5 squares, filled with the image median) before the next search, so a smaller
    board's search never locks onto part of a larger one.
    """
    work = image.copy()
    fill = int(np.median(image))
    ids, pts = [], []
    for plane in sorted(chart.planes, key=lambda p: -len(p.corner_ids())):
        found = detect_board(work, plane.board.pattern)
        if found is None:
            continue
        q, local = found
        ids.append(local + plane.id_offset)
        pts.append(q)
        hull = cv2.convexHull(q.astype(np.float32)).reshape(-1, 2)
        centre = hull.mean(axis=0)
        cols, rows = plane.board.pattern
        grow = 1.0 + 3.0 / min(cols, rows)
        poly = np.rint(centre + grow * (hull - centre)).astype(np.int32)
        cv2.fillConvexPoly(work, poly, fill)
    if not ids:
        return None
    all_ids = np.concatenate(ids)
    return BoardView(chart.object_points_for(all_ids), np.concatenate(pts), all_ids, name)


@dataclass(frozen=True, eq=False)
class SimViews:
    """Detected views of a rendered calibration set."""

    wide: list[BoardView | None]
    tele: list[BoardView | None]
    sizes: tuple[tuple[int, int], tuple[int, int]]
    capture_ids: list[str]
    gt: GroundTruth


def sim_views(folder: Path, pattern: tuple[int, int] = (9, 6), square_m: float = 0.02) -> SimViews:
    """Detect the chart in every image of a rendered ``calibration`` capture set."""
    cs = load_capture_set(folder)
    gt = load_ground_truth(folder)
    three = gt.captures[0].objects[0].name != "board"
    chart = ThreePlaneChart()
    obj = chessboard_object_points(pattern, square_m)
    out: dict[str, list[BoardView | None]] = {"wide": [], "tele": []}
    sizes = {}
    for entry in cs.captures():
        for role in ("wide", "tele"):
            img = read_gray(folder / getattr(entry, role))
            sizes[role] = (img.shape[1], img.shape[0])
            name = f"{entry.id}_{role}"
            if three:
                out[role].append(detect_three_plane(img, chart, name))
                continue
            found = detect_board(img, pattern)
            out[role].append(None if found is None else BoardView(obj[found[1]], *found, name))
    return SimViews(
        out["wide"], out["tele"], (sizes["wide"], sizes["tele"]), [c.id for c in cs.captures()], gt
    )


def true_board_poses(gt: GroundTruth, pattern_square_m: float | None) -> list[Transform]:
    """True ``T_wide_board`` per capture, board = the calibration object-point frame.

    Plain boards: origin at the first inner corner (``chessboard_object_points``), i.e. the
    chart frame shifted by margin + square = 2 squares. Three-plane: the chart frame, from
    the left wall's pose.
    """
    poses = []
    chart = ThreePlaneChart()
    for cap in gt.captures:
        T_wide_world = Transform.from_dict(cap.T_world_device).inverse()
        o = cap.objects[0]
        T_world_obj = Transform.from_dict(o.T_world_chart)
        if pattern_square_m is not None:
            s = pattern_square_m
            T_chart_board = Transform(np.eye(3), np.array([2 * s, 2 * s, 0.0]))
        else:
            T_chart_board = chart.plane(o.name).T_chart_plane.inverse()
        poses.append(T_wide_world @ T_world_obj @ T_chart_board)
    return poses


def true_parameters(
    result: CalibrationResult, views: SimViews, square_m: float | None
) -> np.ndarray:
    """The true parameter vector in ``result``'s layout (cameras and rig of the first capture)."""
    cap = views.gt.captures[0]
    wide, tele = cap.wide.true_camera(), cap.tele.true_camera()
    rel = Transform.from_dict(cap.T_tele_wide)
    lenses = tuple(c.lens for c in result.cameras)
    if any(
        t.lens.name != r.name or t.lens.n_coefficients != r.n_coefficients
        for t, r in zip((wide, tele), lenses, strict=True)
    ):
        raise ValueError("truth is only defined for the true lens model and size")
    layout = Layout(lenses, views.sizes, len(views.wide), stereo=True)
    return layout.pack((wide, tele), rel, tuple(true_board_poses(views.gt, square_m)))


def iid_reference_views(
    views: SimViews, result: CalibrationResult, truth: np.ndarray, rng: np.random.Generator
) -> tuple[list[BoardView | None], list[BoardView | None]]:
    """Wide and tele views with every detected corner replaced by its true projection plus
    iid N(0, σ²) per coordinate, σ = the solve's RMS per coordinate (the exact-covariance
    reference on the same geometry: same poses, corners, ids and lens)."""
    layout = Layout(tuple(c.lens for c in result.cameras), views.sizes, len(views.wide), True)
    sigma = result.rms_px_per_coordinate
    out: list[list[BoardView | None]] = [[], []]
    for cam, seq in enumerate((views.wide, views.tele)):
        for v, bv in enumerate(seq):
            if bv is None:
                out[cam].append(None)
                continue
            n = bv.n_points
            obs = Observations(
                np.full(n, cam), np.full(n, v), bv.object_points, bv.image_points, bv.ids
            )
            r = residuals_and_jacobian(truth, layout, obs, with_jacobian=False)[0]
            true_px = bv.image_points + r.reshape(-1, 2)  # residual = predicted − observed
            noisy = true_px + rng.normal(0.0, sigma, true_px.shape)
            out[cam].append(BoardView(bv.object_points, noisy, bv.ids, bv.name))
    return out[0], out[1]


def z_scores(result: CalibrationResult, truth: np.ndarray) -> np.ndarray:
    """(estimate − truth) / reported σ per parameter."""
    return (result.parameters - truth) / np.sqrt(np.diag(result.covariance))


def render_set(folder: Path, seed: int, config: CalibrationConfig) -> SimViews:
    """Render the ``calibration`` scenario of ``folded-x3`` (every effect on) and detect it."""
    # linear sensor path (isp off): the solver is checked against a sensor-noise model; the
    # presets' phone ISP gives 0.074 px RMS per point on these renders (issue #16)
    spec = load_module("folded-x3").with_effects(isp=False)
    plan = plan_scenario("calibration", spec, seed, config=config)
    write_capture_set(folder, plan)
    return sim_views(folder, config.pattern, config.square_m)


def _rms_pt(res: CalibrationResult, camera: int | None = None) -> float:
    keep = np.ones(res.inliers.size, bool) if camera is None else res.camera_index == camera
    r = res.residuals[keep & res.inliers]
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))


def evaluate_seed(
    seed: int, config: CalibrationConfig, *, compare_even: bool = True, iid_reps: int = 1
) -> dict:
    """Render, detect and calibrate one seed; z-scores against truth and the RMS figures.

    Returns a JSON-ready dict: ``z`` and ``names`` (every parameter of the ``radial-odd``
    solve with the true number of radial terms, 4), RMS per point and per coordinate,
    outliers, seconds, and (``compare_even``) the ``opencv5`` RMS with and without outlier
    rejection beside the odd model's on the same corners.
    """
    with tempfile.TemporaryDirectory() as tmp:
        views = render_set(Path(tmp), seed, config)
    return evaluate_views(views, seed, config, compare_even=compare_even, iid_reps=iid_reps)


def evaluate_views(
    views: SimViews,
    seed: int,
    config: CalibrationConfig,
    *,
    compare_even: bool = True,
    iid_reps: int = 1,
) -> dict:
    """:func:`evaluate_seed` on views already detected.

    ``iid_reps`` > 1 adds ``z_iid_<k>`` and ``mahalanobis2_per_parameter_iid_<k>`` for
    k = 1 … iid_reps − 1: further draws of the iid reference (fresh noise, same geometry and
    σ), for the spread of every figure under an exact covariance."""
    square = None if config.chart == "three-plane" else config.square_m
    odd_opts = CalibrationOptions("radial-odd", n_radial=4)
    odd = calibrate_stereo(views.wide, views.tele, views.sizes, odd_opts)
    truth = true_parameters(odd, views, square)
    err = odd.parameters - truth
    ref = calibrate_stereo(
        *iid_reference_views(views, odd, truth, np.random.default_rng(seed)), views.sizes, odd_opts
    )
    err_ref = ref.parameters - truth
    out: dict = {
        "seed": seed,
        "views": [sum(v is not None for v in views.wide), sum(v is not None for v in views.tele)],
        "names": list(odd.parameter_names),
        "z": (err / np.sqrt(np.diag(odd.covariance))).tolist(),
        # Squared Mahalanobis distance / P: χ²_P / P under the covariance, 1 ± √(2/P).
        "mahalanobis2_per_parameter": float(err @ np.linalg.solve(odd.covariance, err)) / err.size,
        # the same solve on iid-noise corners (exact covariance by construction): the reference
        "z_iid": (err_ref / np.sqrt(np.diag(ref.covariance))).tolist(),
        "mahalanobis2_per_parameter_iid": float(err_ref @ np.linalg.solve(ref.covariance, err_ref))
        / err_ref.size,
        **_iid_draws(views, odd, truth, odd_opts, seed, iid_reps),
        "rms_px_per_point": odd.rms_px_per_point,
        "rms_px_per_coordinate": odd.rms_px_per_coordinate,
        "rms_per_camera": list(odd.rms_per_camera()),
        "outliers": odd.n_outliers,
        "points": int(odd.inliers.size),
        "seconds": odd.seconds,
    }
    if compare_even:
        for reject in (True, False):
            opts = CalibrationOptions("opencv5", reject_outliers=reject)
            even = calibrate_stereo(views.wide, views.tele, views.sizes, opts)
            same = odd
            if not reject:
                opts = CalibrationOptions("radial-odd", n_radial=4, reject_outliers=False)
                same = calibrate_stereo(views.wide, views.tele, views.sizes, opts)
            key = "reject" if reject else "all"
            out[f"even_{key}"] = [_rms_pt(even), _rms_pt(even, 0), _rms_pt(even, 1)]
            out[f"odd_{key}"] = [_rms_pt(same), _rms_pt(same, 0), _rms_pt(same, 1)]
            out[f"even_outliers_{key}"] = even.n_outliers
    return out


def _iid_draws(
    views: SimViews,
    odd: CalibrationResult,
    truth: np.ndarray,
    opts: CalibrationOptions,
    seed: int,
    reps: int,
) -> dict:
    """Draws 1 … reps − 1 of the iid reference (draw 0 is ``z_iid``), keyed ``…_iid_<k>``."""
    out: dict = {}
    for k in range(1, reps):
        rng = np.random.default_rng([seed, k])
        ref = calibrate_stereo(*iid_reference_views(views, odd, truth, rng), views.sizes, opts)
        err = ref.parameters - truth
        out[f"z_iid_{k}"] = (err / np.sqrt(np.diag(ref.covariance))).tolist()
        out[f"mahalanobis2_per_parameter_iid_{k}"] = (
            float(err @ np.linalg.solve(ref.covariance, err)) / err.size
        )
    return out


def z_summary(runs: list[dict], suffix: str = "") -> dict[str, float]:
    """Fraction within 3σ, RMS and max of |z| over all runs: every parameter, and without
    the board poses (cameras + T_tele_wide); and the mean squared Mahalanobis distance per
    parameter (1 for an exact covariance). ``suffix="_iid"``: the same of the iid reference
    (``"_iid_<k>"``: its further draws, see :func:`evaluate_views`)."""
    z = np.concatenate([np.asarray(r["z" + suffix]) for r in runs])
    rig = np.concatenate(
        [np.asarray(r["z" + suffix])[[not n.startswith("view") for n in r["names"]]] for r in runs]
    )
    out = {
        "mean_mahalanobis2_per_parameter": float(
            np.mean([r["mahalanobis2_per_parameter" + suffix] for r in runs])
        )
    }
    for key, v in (("all", z), ("rig", rig)):
        out[f"n_{key}"] = float(v.size)
        out[f"within_3sigma_{key}"] = float(np.mean(np.abs(v) <= 3.0))
        out[f"rms_z_{key}"] = float(np.sqrt(np.mean(v**2)))
        out[f"max_abs_z_{key}"] = float(np.max(np.abs(v)))
    return out
