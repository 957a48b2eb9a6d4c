"""The naive pipeline of thesis §3 (intro) and the acceptance figure of the virtual module:
naive Z = f·B/d on the factory calibration is ~30 % off at 1–4 m on folded-x3
(docs/architecture.md)."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import ShapeError
from phonestereo.evaluation.naive import naive_depth, naive_disparity, naive_relative_errors
from phonestereo.geometry import Camera, Rig, Transform, make_lens
from phonestereo.io import Calibration
from phonestereo.sim.module import EFFECT_NAMES, load_module
from phonestereo.sim.scenarios import plan_scenario

SPEC = load_module("folded-x3")


def _rig(center_m, rotvec_deg=(0.2, -0.3, 0.4)) -> Rig:
    lens = make_lens("opencv5", [-0.05, 0.02, 1e-4, -2e-4, 0.0])
    wide = Camera((2000, 1500), 1500.0, 1500.0, 1003.0, 747.0, lens)
    tele = Camera(
        (2000, 1500), 4500.0, 4500.0, 995.0, 752.0, make_lens("opencv5", [0.01, 0, 0, 0, 0])
    )
    R = Transform.from_rotvec(np.deg2rad(rotvec_deg), [0, 0, 0]).R
    return Rig(wide, tele, Transform(R, -R @ np.asarray(center_m)))


def _points(n: int = 200, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.8, 4.0, n)
    return np.column_stack([rng.uniform(-0.08, 0.08, n) * z, rng.uniform(-0.06, 0.06, n) * z, z])


@pytest.mark.parametrize("center", [(0.0, 0.012, 0.0), (-0.010, 0.0, 0.0), (0.007, 0.007, 0.0)])
def test_exact_when_the_calibration_is_the_truth_and_the_baseline_is_in_plane(center) -> None:
    """Rotation and distortion are undone exactly; eq. 4 holds for any in-plane baseline."""
    rig = _rig(center)
    p = _points()
    qw, qt = rig.project(p)
    z = naive_depth(qw, qt, Calibration(rig))
    assert np.allclose(z, p[:, 2], rtol=1e-9)


def test_z_translation_biases_the_naive_depth() -> None:
    """§3.3: with t_z the naive formula is off by ≈ t_z·y/B (relative, position-dependent)."""
    rig = _rig((0.0, 0.012, 0.0015), (0, 0, 0))
    p = np.array([[0.0, 0.0, 2.0], [0.0, 0.3, 2.0]])  # on axis; 0.15 rad below it
    z = naive_depth(*rig.project(p), Calibration(rig))
    rel = z / p[:, 2] - 1
    # On the axis: d = t_y/(Z − t_z) but B = |t|, so Z_naive/Z = |t|·(Z − t_z)/(t_y·Z).
    assert rel[0] == pytest.approx(np.hypot(12, 1.5) * (2 - 0.0015) / (12 * 2) - 1, abs=1e-9)
    assert abs(rel[1] - rel[0]) > 0.01  # 0.15 rad off axis: the t_z term adds > 1 %


def test_shapes_and_signs() -> None:
    rig = _rig((0.0, 0.012, 0.0))
    qw, qt = rig.project(_points(6).reshape(2, 3, 3))
    assert naive_depth(qw, qt, Calibration(rig)).shape == (2, 3)
    assert np.all(naive_disparity(qw, qt, Calibration(rig)) > 0)  # positive in front
    mirrored = Rig(rig.wide, rig.tele, Transform(rig.T_tele_wide.R, -rig.T_tele_wide.t))
    qw_m, qt_m = mirrored.project(_points(4))
    assert np.isnan(naive_depth(qw_m, qt_m, Calibration(rig))).all()  # d < 0: NaN, not Z < 0
    with pytest.raises(ShapeError):
        naive_depth(qw[0], qt[0, :2], Calibration(rig))


def _median_error(spec, seed: int) -> float:
    """Median over verification captures at 1–4 m of each capture's median relative error."""
    plan = plan_scenario("verification", spec, seed)
    per = []
    for pc in plan.captures:
        corners = pc.truth.objects[0].keypoints["corners"].arrays()
        if 1.0 - 1e-6 <= np.nanmedian(corners.depth_m) <= 4.1:
            per.append(np.median(naive_relative_errors(pc.truth, plan.calibration)))
    return float(np.median(per))


def test_naive_depth_error_is_thesis_like_on_folded_x3() -> None:
    """docs/architecture.md acceptance: 20–40 % median relative error at 1–4 m (thesis ~30 %).

    Per seed (one simulated phone each) the figure varies with the factory-calibration noise:
    seeds 0–9 give 26.1–35.3 % (median 31.7 %); two seeds are checked here."""
    errors = [_median_error(SPEC, seed) for seed in (0, 1)]
    assert all(0.20 <= e <= 0.40 for e in errors), errors
    # With every effect off the naive pipeline is exact on true pixels (nothing else is wrong).
    assert _median_error(SPEC.all_effects_off(), 0) < 1e-6


# 174 scenario plans (6 seeds × every effect off and alone), 327 s in session 26's acceptance
# stage: a printed table, whose one assertion (the 6 seeds' median in 20–40 %) the fast test
# above already makes on seeds 0 and 1 (README's figure). `make bench` runs it, not CI.
@pytest.mark.slow
@pytest.mark.bench
def test_naive_error_breakdown_by_effect(capsys) -> None:
    """Which effect contributes how much (printed with -s; numbers in the report)."""
    seeds = range(6)
    base = [_median_error(SPEC, s) for s in seeds]
    lines = [
        f"all effects on   : median {100 * np.median(base):5.1f} %  per seed "
        f"{np.round(100 * np.array(base), 1).tolist()}"
    ]
    for name in EFFECT_NAMES:
        off = np.median([_median_error(SPEC.with_effects(**{name: False}), s) for s in seeds])
        only = np.median(
            [_median_error(SPEC.all_effects_off().with_effects(**{name: True}), s) for s in seeds]
        )
        lines.append(f"{name:24s} off: {100 * off:5.1f} %   alone: {100 * only:5.1f} %")
    with capsys.disabled():
        print("\n" + "\n".join(lines))
    assert 0.2 <= np.median(base) <= 0.4
