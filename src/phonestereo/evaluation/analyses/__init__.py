"""The chapter-3 analyses (thesis §3.1–§3.6): each reads a capture set, writes figures and a table.

Every analysis is registered in :data:`ANALYSES` under its name, with what it needs from a
capture set and a ``run(capture_set, out_dir)`` that returns an :class:`AnalysisOutput`. The
``phonestereo analyze NAME CAPTURE_SET --out DIR`` command is a thin wrapper over
:func:`run_analysis`; adding an analysis is one module plus one registry entry. The modules
are imported only when run (Matplotlib is slow to import).

Examples
--------
>>> len(ANALYSES), sorted(ANALYSES)[:4]
(8, ['distortion', 'essential', 'handheld', 'heating'])
>>> ANALYSES["heating"].summary
'warm-up drift of the disparity: fit A, τ, saturation time; warm-up gate (§3.1)'
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from phonestereo.errors import InputError
from phonestereo.evaluation.runner import Progress


@dataclass(frozen=True)
class AnalysisOutput:
    """What an analysis produced."""

    #: The analysis name.
    name: str
    #: False when the data could not give the result (the reason says why).
    ok: bool
    #: Why not ok, or notes.
    reason: str
    #: tuple of str. Human-readable lines (the CLI prints them).
    summary: tuple[str, ...]
    #: dict. The JSON table written next to the figures (``<name>.json``).
    table: dict[str, Any]
    #: tuple of Path. Every file written (figures and the table).
    files: tuple[Path, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class AnalysisSpec:
    """A registered analysis: name, one-line summary, what it needs, and where its runner is.

    ``runner`` is ``"module:function"``; the function is called as
    ``function(capture_set_path, out_dir, progress=None)`` and returns an
    :class:`AnalysisOutput`; ``progress(done, total, capture_id)`` is called per capture.
    """

    name: str
    summary: str
    needs: str
    runner: str

    def load(self) -> Callable[..., AnalysisOutput]:
        """Import and return the runner function."""
        module, func = self.runner.split(":")
        fn: Callable[..., AnalysisOutput] = getattr(importlib.import_module(module), func)
        return fn


ANALYSES: dict[str, AnalysisSpec] = {
    "heating": AnalysisSpec(
        "heating",
        "warm-up drift of the disparity: fit A, τ, saturation time; warm-up gate (§3.1)",
        "a static verification chart on a tripod, focus locked, captured from cold every "
        "~10 s for several minutes (>= 4 'verification' captures at distinct time_s), e.g. "
        "`phonestereo simulate heating`",
        "phonestereo.evaluation.analyses.heating:run",
    ),
    "distortion": AnalysisSpec(
        "distortion",
        "residual distortion through e: e over the image and vs radius, the e-axis fix (offset "
        "+ radial polynomial), undistort-both, even vs odd lens model (§3.2)",
        "a flat verification chart filling the tele on a tripod (>= 1 'verification' capture; "
        "several focus distances show Figs. 3-5/3-6), e.g. `phonestereo simulate refocus`; "
        "optional 'calibration' captures (9x6 chessboard, 20 mm) add the even-vs-odd lens "
        "comparison",
        "phonestereo.evaluation.analyses.distortion:run",
    ),
    "translation": AnalysisSpec(
        "translation",
        "non-baseline translation: mean e of two charts at two depths, rotation-only vs "
        "canonical rectification; t_y, t_z measured from e (§3.3)",
        "two verification charts at two depths on a tripod (>= 1 'verification' capture: a "
        "10x8-square 18 mm chart near, the standard chart far), e.g. "
        "`phonestereo simulate dual-depth`",
        "phonestereo.evaluation.analyses.translation:run",
    ),
    "wt-scale": AnalysisSpec(
        "wt-scale",
        "W-T scale per refocus attempt, global and per depth; disparity range before/after; "
        "Table 2 (§3.5.2)",
        "a refocus stack: >= 2 'verification' captures of one or two static charts on a tripod "
        "sharing a focus_group, e.g. `phonestereo simulate refocus` or `dual-depth`",
        "phonestereo.evaluation.analyses.wt_scale:run",
    ),
    "repeatability": AnalysisSpec(
        "repeatability",
        "same-camera refocus repeatability: per-corner range, median normalisation, averaging "
        "(Table 3, §3.5.3)",
        "a refocus stack: >= 2 'verification' captures of one static chart on a tripod sharing "
        "a focus_group, e.g. `phonestereo simulate refocus`",
        "phonestereo.evaluation.analyses.repeatability:run",
    ),
    "orientation": AnalysisSpec(
        "orientation",
        "per-orientation disparity offset from gravity buckets (§3.4, Fig. 3-11)",
        "'verification' captures of one static chart (tripod, heated) in >= 2 device "
        "orientations, each with 'gravity' or an orientation label, e.g. "
        "`phonestereo simulate orientation`",
        "phonestereo.evaluation.analyses.orientation:run",
    ),
    "essential": AnalysisSpec(
        "essential",
        "essential-matrix focus scales (eq. 9) and the Fig. 3-26 variants vs the optimal "
        "correction (§3.5.3)",
        "a refocus stack: >= 2 'verification' captures of one static chart sharing a "
        "'focus_group' (tripod, heated, manual focus), e.g. `phonestereo simulate refocus`",
        "phonestereo.evaluation.analyses.essential:run",
    ),
    "handheld": AnalysisSpec(
        "handheld",
        "optimal scale correction on handheld refocus stacks (§3.5.3, Fig. 3-27)",
        "handheld refocus stacks: >= 2 'verification' captures per 'focus_group', e.g. "
        "`phonestereo simulate handheld`",
        "phonestereo.evaluation.analyses.handheld:run",
    ),
}


def run_analysis(
    name: str,
    capture_set: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    progress: Progress | None = None,
) -> AnalysisOutput:
    """Run the analysis ``name`` on a capture set, writing its figures and table into ``out_dir``.

    Raises
    ------
    InputError
        Unknown analysis (the message lists the known ones), an invalid capture set, or a set
        lacking the captures the analysis needs (the message names them).
    """
    if name not in ANALYSES:
        known = ", ".join(f"{k} ({v.summary})" for k, v in ANALYSES.items())
        raise InputError(f"unknown analysis {name!r}; known analyses: {known}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} exists and is not a folder; choose another folder")
    out.mkdir(parents=True, exist_ok=True)
    return ANALYSES[name].load()(Path(capture_set), out, progress=progress)


__all__ = ["ANALYSES", "AnalysisOutput", "AnalysisSpec", "run_analysis"]
