"""The layers and the ground-truth wall of docs/architecture.md, enforced."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "phonestereo"
PIPELINE = [
    "geometry",
    "io",
    "charts",
    "features",
    "calibration",
    "rectification",
    "fixes",
    "learning",
    "flows",
]


def test_import_linter_contracts_hold() -> None:
    exe = Path(sys.executable).with_name("lint-imports")
    run = subprocess.run([str(exe)], cwd=SRC.parents[1], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def test_no_pipeline_module_reads_ground_truth() -> None:
    offenders = []
    for pkg in PIPELINE:
        for path in (SRC / pkg).rglob("*.py"):
            if re.search(r"ground_truth", path.read_text()):
                offenders.append(str(path.relative_to(SRC)))
    assert not offenders, f"pipeline modules mention ground truth: {offenders}"
