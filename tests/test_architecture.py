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


def test_no_import_cycle_between_phonestereo_modules() -> None:
    import grimp  # import-linter's graph builder

    graph = grimp.build_graph("phonestereo")
    cycles = sorted(
        (m, imp)
        for m in graph.modules
        for imp in graph.find_modules_directly_imported_by(m)
        if graph.find_shortest_chain(importer=imp, imported=m)
    )
    # One concept per module, layers downward: no module imports one that imports it back
    # (io/calibration.py ↔ io/opencv_yaml.py was the last cycle, issue #19).
    assert not cycles, f"import cycles: {cycles}"


def test_tests_and_benchmarks_share_helpers_only_through_support() -> None:
    root = SRC.parents[1]
    # No test execs a benchmark; no benchmark imports a test module (helpers: tests/_support).
    execs = [
        str(p.relative_to(root))
        for p in (root / "tests").rglob("*.py")
        if p.name != "test_architecture.py"
        and re.search(r"spec_from_file_location|benchmarks[\"']? */ *[\"']bench_", p.read_text())
    ]
    imports = [
        str(p.relative_to(root))
        for p in (root / "benchmarks").glob("*.py")
        if re.search(r"^\s*(from|import) +(tests\.|test_|conftest)", p.read_text(), re.M)
    ]
    assert not execs and not imports, (execs, imports)
