"""Run every ``benchmarks/bench_*.py`` script with ``--json`` and print one summary table.

Usage: ``.venv/bin/python benchmarks/run_all.py [NAME ...]`` (names without ``bench_``/``.py``).
Each script measures speed as seconds or as a ratio against the obvious alternative in the same
run (docs/architecture.md); this runner only collects their JSON lines.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(names: list[str]) -> int:
    scripts = sorted(HERE.glob("bench_*.py"))
    if names:
        scripts = [s for s in scripts if s.stem.removeprefix("bench_") in names]
    failed = 0
    for script in scripts:
        run = subprocess.run(
            [sys.executable, str(script), "--json"], capture_output=True, text=True
        )
        lines = [ln for ln in run.stdout.splitlines() if ln.startswith("{")]
        if run.returncode != 0 or not lines:
            failed += 1
            print(f"{script.stem}: FAILED (exit {run.returncode})\n{run.stderr[-2000:]}")
            continue
        print(f"{script.stem}: {json.dumps(json.loads(lines[-1]))}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
