"""A calibration whose rectified rows are off by more than the coarse step searches (issue #18,
held-out random-3056: after warm-up its factory rectification's rows were 11–12 px off, the
coarse step searched ±8 rows, no face capture was learned and no chart measured).

The row error is searched for (the coarse step's rows move when its peak lies on their
border), the faces are searched about the rows the W-T measurement found, the observations
record their e, and the application centres its rows on the learned e.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from _support.face_chart import tele_principal_point_off, write_face_chart_set
from phonestereo.flows import learning
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.face_backends import CachedBackend, default_backend
from phonestereo.flows.face_wt import measure_wt, wt_box
from phonestereo.flows.roi_config import RoiConfig, centred_rows
from phonestereo.flows.roi_disparity import measure_roi, reference_rectification
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.io import load_calibration, load_capture_set, read_gray
from phonestereo.learning.observation import Observation, typical_row_error_px
from phonestereo.rectification import Rectification


def _rig() -> Rig:
    wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    return Rig(wide, wide.scaled(3.0), Transform.from_rotvec([0.001, -0.002, 0.003],
                                                             [0.0, -0.012, 0.001]))


@pytest.mark.parametrize("shift", [5.0, -12.0, 0.4])
def test_moving_the_tele_rows_moves_its_rectified_points_by_exactly_that(shift: float) -> None:
    rect = Rectification.from_rig(_rig(), "canonical")
    moved = rect.with_tele_rows(shift)
    q = np.array([[100.0, 200.0], [1500.0, 900.0], [999.5, 749.5]])
    np.testing.assert_allclose(moved.points_wide(q), rect.points_wide(q), atol=1e-12)
    np.testing.assert_allclose(moved.points_tele(q) - rect.points_tele(q),
                               np.tile([0.0, shift], (3, 1)), atol=1e-9)
    # and back: a rectified tele point maps to the same raw pixel once the shift is undone
    back = moved.unrectify_tele(rect.points_tele(q) + np.array([0.0, shift]))
    np.testing.assert_allclose(back, q, atol=1e-6)
    assert moved.with_tele_rows(shift) is moved and rect.with_tele_rows(0.0) is rect
    assert moved.options.to_dict()["tele_row_shift_px"] == shift
    assert "tele_row_shift_px" not in rect.options.to_dict()  # old JSON unchanged


def test_whole_pixel_row_shift_resamples_the_same_pixels() -> None:
    """An integer shift moves the rectified tele image by whole rows: the same raw pixels,
    read at maps that differ by their spline grid only (< 0.01 px)."""
    rect = Rectification.from_rig(_rig(), "canonical")
    moved = rect.with_tele_rows(7.0)
    mx, my = rect.maps_tele()
    nx, ny = moved.maps_tele()
    ok = (mx[:-7] > 0) & (nx[7:] > 0)
    assert ok.mean() > 0.9
    assert np.abs(nx[7:][ok] - mx[:-7][ok]).max() < 0.01
    assert np.abs(ny[7:][ok] - my[:-7][ok]).max() < 0.01


def test_centred_rows_leave_small_row_errors_alone() -> None:
    cfg = RoiConfig()  # ±8 rows, 3 px kept to spare
    assert [centred_rows(cfg, e) for e in (0.0, 5.0, -5.0, 5.6, -11.6)] == [0, 0, 0, 6, -12]
    assert centred_rows(replace(cfg, coarse_rows=3), 1.2) == 1


def test_the_learned_row_error_is_the_bucket_median() -> None:
    obs = [Observation(900.0, 700.0, 10.0, 10.0, 1.5, "landscape", "", 300.0, None, f"c{k}",
                       e_measured_px=e) for k, e in enumerate((11.0, 12.0, 12.5, float("nan")))]
    assert typical_row_error_px(obs) == 12.0
    assert np.isnan(typical_row_error_px(obs[3:]))  # not recorded: no centring
    c = Corrector(obs, FlowConfig())
    assert c.row_error_px("landscape") == 12.0


def test_the_learned_row_error_is_read_where_the_roi_is() -> None:
    """random-3056's faces read e from 3 px at the top of the tele's view to 15 px at its bottom
    (its W-T scale is 1.3 % off): the plane through them is read at the ROI, not their median;
    a mispaired face does not move it."""
    rng = np.random.default_rng(0)
    xy = rng.uniform([200, 80], [1100, 1000], (24, 2))
    e = 3.0 + 0.013 * (xy[:, 1] - 80) - 0.002 * (xy[:, 0] - 200) + rng.normal(0, 0.3, 24)
    e[5] = 40.0
    obs = [Observation(x, y, 10.0, 10.0, 1.5, "landscape", "", 300.0, None, f"c{k}",
                       e_measured_px=v) for k, (x, y, v) in enumerate(zip(*xy.T, e, strict=True))]
    for at in ((650.0, 100.0), (650.0, 950.0), (300.0, 500.0)):
        truth = 3.0 + 0.013 * (at[1] - 80) - 0.002 * (at[0] - 200)
        assert abs(typical_row_error_px(obs, at) - truth) < 0.3
    # too few or not spread: the median
    assert typical_row_error_px(obs[:5], (650.0, 950.0)) == np.median(e[:5])


@pytest.fixture(scope="module")
def rows_set(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The 1.5 m face-chart capture of ``folded-x3`` (its baseline is vertical: the rectified
    rows run along the raw tele's x) with a calibration whose tele c_x is 40 px off: its
    rectified rows are ~13 px off, beyond the coarse step's ±8."""
    folder = write_face_chart_set(tmp_path_factory.mktemp("rows_set"))
    return folder, tele_principal_point_off(folder, 0, -40.0, "calibration_rows.json")


def test_a_row_error_beyond_the_coarse_rows_is_measured(rows_set: tuple[Path, Path]) -> None:
    folder, cal_path = rows_set
    cs = load_capture_set(folder)
    images = tuple(read_gray(p) for p in cs.image_paths(cs.captures()[0].id))
    cfg = FlowConfig()
    good = load_calibration(cs.calibration_path()).rig
    off = load_calibration(cal_path).rig
    ref_good, ref_off = (reference_rectification(r, cfg.mode) for r in (good, off))
    m0 = measure_wt(cfg, good, images, wt_box(ref_good), ref_good)  # type: ignore[arg-type]
    m1 = measure_wt(cfg, off, images, wt_box(ref_off), ref_off)  # type: ignore[arg-type]
    assert m0.ok and "row_offset_px" not in m0.counts
    # the coarse peak sat on the border (8 rows) and was searched again about it
    assert m1.ok and abs(m1.counts["row_offset_px"]) >= 8
    assert 11 <= abs(m1.counts["coarse_e_px"]) <= 15
    # the rows moved, not the disparities: the same as a search over ±16 rows about 0 (the
    # two differ by < 0.001 px; the right calibration's 0.55 px apart, as its W-T scale is)
    wide = replace(cfg, roi=replace(cfg.roi, coarse_rows=16))
    m16 = measure_wt(wide, off, images, wt_box(ref_off), ref_off)  # type: ignore[arg-type]
    assert m16.ok and "row_offset_px" not in m16.counts
    assert abs(np.median(m1.d) - np.median(m16.d)) < 0.01
    # told the row error, the first search finds it (no second one) and measures the same
    # surface: 0.037 px apart over ~700 matches of 0.25 px scatter (other rows moved by 12
    # instead of 8 px keep other matches at the crop's edges)
    match = replace(cfg.roi.match, max_keypoints=int(cfg.face_wt_keypoints))
    roi_cfg = replace(cfg.roi, expand=1.0, coarse_expand=1.0, match=match)  # as measure_wt
    told = m1.counts["coarse_e_px"]
    m2 = measure_roi(off, *images, wt_box(ref_off), roi_cfg, ref_off,  # type: ignore[arg-type]
                     row_offset_px=told)
    assert m2.ok and m2.counts["row_offset_px"] == told
    assert abs(np.median(m2.d) - np.median(m1.d)) < 0.05


def test_faces_are_searched_about_the_rows_the_wt_measurement_found(
    rows_set: tuple[Path, Path],
) -> None:
    folder, cal_path = rows_set
    cs = load_capture_set(folder)
    det = CachedBackend(default_backend())
    entry = cs.captures()[0]
    good = learning.learn_face_capture(FlowConfig(), cs, entry, load_calibration(
        cs.calibration_path()), det)
    off = learning.learn_face_capture(FlowConfig(), cs, entry, load_calibration(cal_path), det)
    assert good.ok and "row_offset_px" not in good.stages
    assert off.ok, off.reason
    assert abs(off.stages["row_offset_px"]) >= 11
    e = np.array([o.e_measured_px for o in off.observations])
    assert np.all((np.abs(e) > 10) & (np.abs(e) < 16))  # in the calibration's own frame
    e_good = np.array([o.e_measured_px for o in good.observations])
    assert np.all(np.abs(e_good) < 3)
    # the same faces; their corrections differ by what the wrong c_x does to the W-T scale
    # (the chart's surface reads 0.55 px less under it, test above)
    c0 = np.median([o.d_expected_px - o.d_measured_px for o in good.observations])
    c1 = np.median([o.d_expected_px - o.d_measured_px for o in off.observations])
    assert len(off.observations) == len(good.observations)
    assert abs(c1 - c0 - 0.55) < 0.15
