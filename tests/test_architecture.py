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


def _calls(attr: str) -> list[str]:
    """Modules of src/ that call ``<anything>.attr(...)`` or ``attr(...)``."""
    import ast

    found = []
    for path in SRC.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if name == attr:
                    found.append(str(path.relative_to(SRC)))
    return sorted(set(found))


def test_one_learning_path() -> None:
    # Issue #19: observations are made only by the learning flow (gates, focus calibration,
    # W-T scale, store context). A second path that writes the store or runs the landmark
    # block on its own (as learning/learn.py's learn_capture_set did) fails here.
    assert _calls("add_capture") == ["flows/learning.py"]
    assert _calls("learn_capture") == ["flows/learning.py"]
    assert _calls("learn_face_capture") == ["flows/learning.py"]
