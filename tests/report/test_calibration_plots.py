"""Residual plots of a calibration: panels, colours, files, and `phonestereo calibrate --plots`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import PathCollection
from matplotlib.quiver import Quiver
from PIL import Image
from typer.testing import CliRunner

from phonestereo.calibration.solve import CalibrationOptions, calibrate_camera, calibrate_stereo
from phonestereo.calibration.views import BoardView, chessboard_object_points
from phonestereo.cli import app
from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Transform, make_lens
from phonestereo.report.calibration_plots import (
    INLIER_COLOR,
    OUTLIER_COLOR,
    residual_figure,
    write_residual_plots,
)

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "opencv_stereo"
CAM = Camera((1000, 750), 800.0, 800.0, 505.0, 371.0, make_lens("opencv5", [-0.1, 0.03, 0, 0, 0]))
N_OUTLIERS = 4


def _views(cam: Camera, poses: list[Transform], seed: int, outliers: int) -> list[BoardView]:
    rng = np.random.default_rng(seed)
    obj = chessboard_object_points((9, 6), 0.025)
    views = []
    for i, T in enumerate(poses):
        q = cam.project(T.apply(obj)) + rng.normal(0, 0.1, (len(obj), 2))
        if i < outliers:  # one gross outlier (3 px) in each of the first views
            q[7] += 3.0
        views.append(BoardView(obj, q, np.arange(len(obj)), f"v{i}"))
    return views


def _poses(n: int, seed: int = 1) -> list[Transform]:
    rng = np.random.default_rng(seed)
    return [
        Transform.from_rotvec(
            rng.normal(0, 0.3, 3) * [1, 1, 0.2],
            [rng.uniform(-0.15, 0.0), rng.uniform(-0.1, 0.0), rng.uniform(0.35, 0.5)],
        )
        for _ in range(n)
    ]


@pytest.fixture(scope="module")
def mono():
    return calibrate_camera(_views(CAM, _poses(8), 0, N_OUTLIERS), CAM.size)


def test_figure_has_the_two_panels_with_units(mono) -> None:
    fig = residual_figure(mono, 0)
    ax_q, ax_r = fig.axes[:2]
    assert len(fig.axes) == 2
    assert "residual vectors" in ax_q.get_title() and "vs radius" in ax_r.get_title()
    assert ax_q.get_xlabel() == "x [px]" and ax_q.get_ylabel() == "y [px]"
    assert "[px]" in ax_r.get_xlabel() and "[px]" in ax_r.get_ylabel()
    assert ax_q.get_ylim()[0] > ax_q.get_ylim()[1]  # image convention: y grows downwards
    assert "per point" in fig.get_suptitle() and "per coordinate" in fig.get_suptitle()


def test_inliers_and_outliers_are_coloured_apart(mono) -> None:
    gross = (mono.ids == 7) & (mono.view_index < N_OUTLIERS)
    assert not mono.inliers[gross].any()  # the 3 px points are rejected (σ = 0.1 px) ...
    assert mono.n_outliers <= N_OUTLIERS + 3  # ... with at most a few 99.7 % tail points
    fig = residual_figure(mono, 0)
    quivers = [c for c in fig.axes[0].collections if isinstance(c, Quiver)]
    counts = sorted(q.N for q in quivers)
    assert counts == [mono.n_outliers, mono.inliers.size - mono.n_outliers]
    colours = {tuple(np.round(q.get_facecolor()[0][:3], 3)) for q in quivers}
    assert len(colours) == 2
    scatters = [c for c in fig.axes[1].collections if isinstance(c, PathCollection)]
    sizes = [len(s.get_offsets()) for s in scatters]  # inliers, then outliers (near, far)
    assert sizes[0] == counts[1] and sum(sizes[1:]) == counts[0]
    assert INLIER_COLOR != OUTLIER_COLOR


def test_stereo_writes_one_png_per_camera(tmp_path: Path) -> None:
    tele = Camera((1000, 750), 1600.0, 1600.0, 498.0, 380.0, make_lens("opencv5", [0.0] * 5))
    rel = Transform.from_rotvec([0.002, -0.003, 0.001], [0.0, -0.012, 0.0015])
    poses = _poses(8, 2)
    wide_v = _views(CAM, poses, 3, 0)
    tele_v = []
    for v, T in zip(_views(tele, [rel @ T for T in poses], 4, 0), poses, strict=True):
        ok = tele.contains(tele.project((rel @ T).apply(v.object_points)), margin=2)
        tele_v.append(v.subset(ok) if ok.sum() >= 12 else None)
    res = calibrate_stereo(wide_v, tele_v, (CAM.size, tele.size), CalibrationOptions())
    paths = write_residual_plots(res, tmp_path / "plots", dpi=50)
    assert [p.name for p in paths] == ["residuals_wide.png", "residuals_tele.png"]
    for p in paths:
        with Image.open(p) as im:
            assert im.size == (650, 260)  # 13 × 5.2 inches at 50 dpi
            assert np.asarray(im.convert("L")).std() > 10  # not a blank canvas


def test_bad_requests(mono, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="camera must be 0"):
        residual_figure(mono, 1)
    with pytest.raises(InputError, match="one entry per camera"):
        write_residual_plots(mono, tmp_path, names=["a", "b"])
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        write_residual_plots(mono, tmp_path / "file")


@pytest.mark.skipif(not DATA.exists(), reason="shared/data not beside the clone")
def test_cli_calibrate_writes_plots(tmp_path: Path) -> None:
    args = ["calibrate", "--board", "9x6", "--square-m", "1", "--wide", str(DATA / "left*.jpg")]
    args += ["--tele", str(DATA / "right*.jpg"), "--out", str(tmp_path / "calibration.json")]
    res = CliRunner().invoke(app, [*args, "--plots", str(tmp_path / "plots"), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output.strip().splitlines()[-1])
    names = sorted(Path(p).name for p in summary["plots"])
    assert names == ["residuals_tele.png", "residuals_wide.png"]
    assert all((tmp_path / "plots" / n).stat().st_size > 20_000 for n in names)
