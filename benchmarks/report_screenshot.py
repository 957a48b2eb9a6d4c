"""The bench's HTML report in a real browser (issue #7): a headless Chromium screenshot.

Runs the thesis bench on a small capture set (6 face + 3 verification captures rendered on
the ``folded-x3`` module, or ``--set DIR``), writes the HTML report
(:func:`phonestereo.report.bench_report.write_report`), then opens it in headless Chromium and
saves a full-page screenshot. The screenshot is checked to hold the figures: the report has
≥ 2 embedded PNGs, and the screenshot is not blank (share of non-white pixels, number of
distinct colours of every 2nd pixel: a report with its three figures gives ~2000, one with
two ~650, the same page without its ``<img>`` tags ~250 from anti-aliased text).

When no Chromium is installed the script says so and exits 0 with ``skipped``.

Run: ``.venv/bin/python benchmarks/report_screenshot.py [--set DIR] [--out DIR] [--json]``
(Debian: ``apt-get install -y chromium``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome executable on PATH (or Debian's /usr/bin/chromium), or None."""
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").is_file() else None


def screenshot(
    html_path: Path, png_path: Path, *, size: tuple[int, int] = (1100, 2400), timeout_s: float = 120
) -> Path:
    """Headless Chromium screenshot of a local HTML file.

    Raises
    ------
    FileNotFoundError
        No Chromium on PATH.
    RuntimeError
        Chromium failed or wrote no PNG (its stderr tail in the message).
    """
    exe = find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium on PATH (Debian: apt-get install -y chromium)")
    png_path = Path(png_path).resolve()
    png_path.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory(prefix="chromium_profile_") as profile:
        cmd = [
            exe, "--headless", "--disable-gpu", "--no-sandbox", "--disable-dev-shm-usage",
            "--hide-scrollbars", f"--user-data-dir={profile}", f"--screenshot={png_path}",
            f"--window-size={size[0]},{size[1]}", Path(html_path).resolve().as_uri(),
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False)
    if not png_path.is_file():
        tail = (proc.stderr or "").strip().splitlines()[-5:]
        raise RuntimeError(f"chromium wrote no screenshot (exit {proc.returncode}): {tail}")
    return png_path


def screenshot_stats(png_path: Path) -> dict[str, Any]:
    """Size, share of non-white pixels and number of distinct colours of a screenshot."""
    from PIL import Image

    img = np.asarray(Image.open(png_path).convert("RGB"))
    non_white = np.any(img < 245, axis=2)
    colours = np.unique(img[::2, ::2].reshape(-1, 3), axis=0)
    return {
        "size": [int(img.shape[1]), int(img.shape[0])],
        "non_white_fraction": round(float(non_white.mean()), 4),
        "distinct_colours": len(colours),
    }


def render_small_set(out: Path, seed: int = 0, workers: int = 2) -> Path:
    """Render a small ``thesis-bench`` (6 face + 3 verification captures) into ``out``.

    ``BenchConfig.quick()`` is not used: its four face captures (1.5 m, two positions) can all
    be gated (W-T scale), which leaves a report without learned correction or errors.
    """
    from phonestereo.sim.module import load_module
    from phonestereo.sim.scenarios import (
        BenchConfig,
        LearningConfig,
        VerificationConfig,
        plan_scenario,
    )
    from phonestereo.sim.writer import write_capture_set

    cfg = BenchConfig(
        LearningConfig(distances_m=(1.0, 2.0), positions=((0, 0), (0.5, 0), (0, 0.5)), attempts=1),
        VerificationConfig(distances_m=(1.0, 2.0, 3.0), attempts=1),
    )
    plan = plan_scenario("thesis-bench", load_module("folded-x3"), seed, config=cfg)
    write_capture_set(out, plan, workers=workers)
    return out


def run(set_dir: Path | None, out_dir: Path) -> dict[str, Any]:
    """Bench → report → screenshot; the numbers of each step."""
    from phonestereo.evaluation.bench import run_bench
    from phonestereo.report.bench_report import write_report

    t0 = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    if set_dir is None:
        set_dir = render_small_set(out_dir / "set")
    t1 = time.perf_counter()
    res = run_bench(set_dir)
    t2 = time.perf_counter()
    report = write_report(res, out_dir / "report.html", title="phonestereo report screenshot")
    text = report.read_text(encoding="utf-8")
    out: dict[str, Any] = {
        "capture_set": str(set_dir), "report": str(report),
        "report_kb": round(len(text) / 1024, 1),
        "embedded_png": text.count('src="data:image/png;base64,'),
        "render_s": round(t1 - t0, 1), "bench_s": round(t2 - t1, 1),
        "full_median_rel_err": res["stages"]["full"]["median_rel_err"],
    }
    png = out_dir / "report.png"
    try:
        t3 = time.perf_counter()
        screenshot(report, png)
        out["screenshot"] = str(png)
        out["screenshot_s"] = round(time.perf_counter() - t3, 1)
        out.update(screenshot_stats(png))
        out["status"] = (
            "ok" if out["embedded_png"] >= 2 and out["distinct_colours"] >= 500 else "no figures"
        )
    except FileNotFoundError as err:
        out["status"] = "skipped"
        out["reason"] = str(err)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", type=Path, default=None, help="reuse a rendered thesis-bench set")
    ap.add_argument("--out", type=Path, default=None, help="folder for report + screenshot")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = ap.parse_args()
    if find_chromium() is None:
        print("chromium not found (Debian: apt-get install -y chromium): skipped")
        return
    out_dir = args.out or Path(tempfile.mkdtemp(prefix="report_screenshot_"))
    res = run(args.set, out_dir)
    if args.json:
        print(json.dumps(res, indent=1))
        return
    for k, v in res.items():
        print(f"{k:24s} {v}")
    if res["status"] == "skipped":
        print("skipped")


if __name__ == "__main__":
    main()
