"""The bench's HTML report: sections and embedded figures from a hand-made bench result, and a
headless Chromium screenshot that shows them (skipped when no Chromium is installed).

No rendering: the capture set is ``thesis-bench`` quick planned with ``render=False`` (JSON
only), plus flat synthetic wide/tele PNGs written directly (the report draws the wide images
of a few captures with their ROIs; any content will do). The learned observations are made by
hand over the reference rectified frame, so the correction figure has something to fit.
"""

from __future__ import annotations

import base64
import io
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from phonestereo.flows.roi_disparity import reference_rectification
from phonestereo.io import load_calibration, load_capture_set, write_image
from phonestereo.learning.observation import Observation
from phonestereo.report.bench_report import write_report
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import plan_scenario
from phonestereo.sim.writer import IMAGE_DIR, write_capture_set

DISTANCES_M = (1.0, 3.0)  # BenchConfig.quick()'s verification distances


def _stage(med: float | None, p90: float | None) -> dict[str, Any]:
    return {"median_rel_err": med, "p90_rel_err": p90, "n": 0 if med is None else 2}


def _observations(cs_root: Path) -> list[Observation]:
    """36 observations on a 6 × 6 grid of the reference frame, correction 0.2 + 1e-4·x px."""
    cal = load_calibration(load_capture_set(cs_root).calibration_path())
    w, h = reference_rectification(cal.rig).wide_rect.size
    xs, ys = np.meshgrid(np.linspace(20, w - 20, 6), np.linspace(20, h - 20, 6))
    out = []
    for i, (x, y) in enumerate(zip(xs.ravel(), ys.ravel(), strict=True)):
        d = 9.0 + 0.5 * (i % 3)
        out.append(Observation(
            x_px=float(x), y_px=float(y), d_measured_px=d, d_expected_px=d + 0.2 + 1e-4 * x,
            depth_m=2.0, orientation="landscape", focus_group=None, time_s=300.0 + i,
            temperature_c=None, capture_id=f"L{i // 6:02d}", sigma_px=0.05,
        ))
    return out


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    root = tmp_path_factory.mktemp("bench_report") / "set"
    plan = plan_scenario("thesis-bench", load_module("folded-x3"), 0, quick=True)
    write_capture_set(root, plan, render=False)
    rig = plan.calibration.rig
    for entry in plan.manifest(IMAGE_DIR).captures:  # flat synthetic images (fast PNGs)
        for rel, cam in ((entry.wide, rig.wide), (entry.tele, rig.tele)):
            w, h = cam.size
            img = np.broadcast_to(np.linspace(40, 200, w, dtype=np.uint8), (h, w))
            write_image(root / rel, np.ascontiguousarray(img))
    cs = load_capture_set(root)
    n_ver = sum(c.kind == "verification" for c in cs.captures())
    per_distance = [
        {"distance_m": d, "naive": _stage(0.1 * d, 0.12 * d), "measured": _stage(0.08, 0.1),
         "full": _stage(0.004, 0.009), "cramer_rao_floor": _stage(0.002, 0.003)}
        for d in DISTANCES_M
    ]
    obs = _observations(root)
    bench = {
        "capture_set": str(root),
        "stages": {"naive": _stage(0.2, 0.3), "measured": _stage(0.08, 0.1),
                   "full": _stage(0.004, 0.009), "cramer_rao_floor": _stage(0.002, 0.003),
                   "within_sigma": 0.75, "gated": 0},
        "captures": [{"capture_id": f"V{i}"} for i in range(n_ver)],
        "learning": {"n_observations": len(obs)},
        "per_distance": per_distance,
        "ablation": [{"without": "wt_scale", "median_rel_err": 0.03, "p90_rel_err": 0.05,
                      "gated": 1}],
        "_observations": obs,
    }
    path = write_report(bench, root.parent / "report.html", title="report test")
    return path, bench


def _pngs(text: str) -> list[Image.Image]:
    data = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    return [Image.open(io.BytesIO(base64.b64decode(d))) for d in data]


def test_report_has_sections_table_and_figures(report: tuple[Path, dict[str, Any]]) -> None:
    path, bench = report
    text = path.read_text(encoding="utf-8")
    assert text.startswith("<!doctype html>")
    for section in (
        "<h1>report test</h1>",
        "<h2>Relative depth error per stage</h2>",
        "<h2>Ablation: each fix switched the other way in turn</h2>",
        "<h2>Figures</h2>",
    ):
        assert section in text
    # The stage table: one row per distance plus the "all" row, numbers as percentages.
    assert "<td>1.0 m</td>" in text and "<td>3.0 m</td>" in text and "<b>all</b>" in text
    assert "0.40 %" in text  # full-flow median 0.004
    assert f"{len(bench['_observations'])} learned face observations" in text
    # Error vs distance, the captures with ROIs, the learned correction: three real PNGs.
    imgs = _pngs(text)
    assert len(imgs) >= 2
    assert len(imgs) == 3  # observations given → the correction figure too
    for im in imgs:
        a = np.asarray(im.convert("RGB"))
        assert min(im.size) >= 200  # figsize × 100 dpi: at least 2.9 in tall
        assert len(np.unique(a.reshape(-1, 3), axis=0)) >= 20  # drawn content, not a blank


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        if shutil.which(name):
            return shutil.which(name)
    # Debian's package, also when PATH is minimal (CI runners, sudo)
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").is_file() else None


def test_report_screenshot_in_headless_chromium(
    report: tuple[Path, dict[str, Any]], tmp_path: Path
) -> None:
    exe = _chromium()
    if exe is None:
        pytest.skip("chromium not installed (Debian: apt-get install -y chromium)")
    path, _ = report
    png = tmp_path / "report.png"
    cmd = [exe, "--headless", "--disable-gpu", "--no-sandbox", "--disable-dev-shm-usage",
           "--hide-scrollbars", f"--user-data-dir={tmp_path / 'profile'}",
           f"--screenshot={png}", "--window-size=1100,2400", path.resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert png.is_file(), proc.stderr[-2000:]
    a = np.asarray(Image.open(png).convert("RGB"))
    assert a.shape[:2] == (2400, 1100)
    # The page holds the figures. Measured on this report: 14 % ink, ~1050 colours (every
    # 2nd pixel), ~19 000 viridis pixels; the same page with the <img> tags removed: 2 % ink,
    # ~250 colours (anti-aliased text), no viridis pixel.
    assert np.any(a < 245, axis=2).mean() > 0.06
    assert len(np.unique(a[::2, ::2].reshape(-1, 3), axis=0)) >= 500
    # The correction figure's viridis colours are on the page (yellow-green to purple).
    viridis = (a[..., 1] > 150) & (a[..., 2] < 120) & (a[..., 0] < 230) & (a[..., 0] > 100)
    assert viridis.sum() > 2000
