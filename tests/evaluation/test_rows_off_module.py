"""random-3056, drawn beyond the acceptance seeds (issue #18's ranges): a ×3.6 periscope whose
factory rectification's rows are 11–12 px off after warm-up (principal points drifted (5.2, 3.7)
px in the wide and (−2.3, −5.4) px in the tele, factory noise ×3). The coarse step searched ±8
rows about e = 0: no face capture was learned and none of its 18 charts was measured (and at
3.2–4 m the rows about 0 held a chessboard alias 30–37 px off, which learning would have turned
into confident wrong depths).

With the rows moved to a border peak, the faces searched about the rows the W-T measurement
found and the application's rows centred on the learned row error (session 22): 14 of 15 face
captures learned, 18 of 18 charts measured, full flow 1.14 % median, 2.67 % p90, 28 % within
σ, largest |error| 2.3σ. The accuracy is above the 1 % line: even with the ruler, the faces'
and the chart's disparities all replaced by the truth (benchmarks/bench_common_mode.py
``RFCQ``) the set reads −0.49 % ± 0.83 %, a correction that runs from +1.6 % at 0.8 m to
−2.9 % at 4 m — the learned field, not the measurement (docs/module-random.md, session 22).
"""

from __future__ import annotations

import numpy as np
import pytest

from _support.drawn_module import bench_drawn_module


@pytest.mark.slow  # ~3 min on one core: 33 captures rendered, learned and applied
def test_rows_off_by_12_px_are_learned_and_measured(tmp_path) -> None:
    res = bench_drawn_module(3056, tmp_path)
    caps = [c for c in res["captures"] if c["ok"]]
    # before: 0 of 18 measured (every chart gated `learned`: no face capture learned)
    assert len(caps) >= 0.8 * len(res["captures"]), [c["reason"] for c in res["captures"]]
    # never a confident wrong number: measured 2.3σ at most (the 4σ line of issue #18)
    z = np.array([abs(c["depth_m"] - c["z_true_m"]) / c["sigma_m"] for c in caps])
    assert z.max() <= 4.0, z
    # the chessboard aliases about e = 0 read 3.4× too near: none is left (largest 3.0 %)
    err = np.array([abs(c["depth_m"] / c["z_true_m"] - 1) for c in caps])
    assert err.max() < 0.05, err
    full = res["stages"]["full"]
    # 1.14 % / 2.67 % measured: above the 1 % line (module docstring); this bounds a regression
    assert full["median_rel_err"] <= 0.015 and full["p90_rel_err"] <= 0.035, full
