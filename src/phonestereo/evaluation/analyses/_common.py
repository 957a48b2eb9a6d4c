"""Helpers every chapter-3 analysis shares: the capture set and its rig, the captures of a
kind, writing the JSON table, figure saving, JSON cleaning, per-corner maps."""

from __future__ import annotations

import functools
import inspect
import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Concatenate, NamedTuple, ParamSpec, TypeVar

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from phonestereo.errors import InputError
from phonestereo.evaluation.analyses import AnalysisOutput, Progress
from phonestereo.geometry import Rig
from phonestereo.io import CaptureEntry, CaptureSet, load_calibration, load_capture_set
from phonestereo.rectification import Rectification

F64 = np.ndarray
T = TypeVar("T")
P = ParamSpec("P")
S = TypeVar("S")  # the opened set an analysis body takes


def save_figure(fig: Figure, path: Path) -> Path:
    """Render a Matplotlib figure (Agg) to ``path`` (PNG, 110 dpi)."""
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    return path


def map_panel(fig: Figure, ax: Any, xy: F64, v: F64, title: str, label: str, **kw: Any) -> None:
    """Scatter of per-corner values at their (rectified wide) pixels, with a colour bar."""
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=v, s=10, cmap=kw.pop("cmap", "viridis"), **kw)
    fig.colorbar(sc, ax=ax, label=label)
    ax.set_title(title, fontsize=9)
    image_axes(ax)


def image_axes(ax: Any) -> None:
    """Axes over the rectified image: x and y labelled in pixels, y down, equal aspect."""
    ax.set_xlabel("rectified x [px]")
    ax.set_ylabel("rectified y [px]")
    ax.invert_yaxis()
    ax.set_aspect("equal")


def label_axes(
    ax: Any, title: str, xlabel: str, ylabel: str, *, legend_fontsize: float | None = None
) -> None:
    """The analyses' plot style: ``title``, the axis labels, a light grid, and a legend in
    ``legend_fontsize`` points when one is given."""
    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if legend_fontsize is not None:
        ax.legend(fontsize=legend_fontsize)


def json_clean(v: Any) -> Any:
    """JSON-safe copy: private ``_`` keys dropped, NaN/inf → None, NumPy → Python.

    >>> json_clean({"a": np.float64("nan"), "_big": [1], "b": np.arange(2)})
    {'a': None, 'b': [0, 1]}
    """
    if isinstance(v, dict):
        return {k: json_clean(x) for k, x in v.items() if not str(k).startswith("_")}
    if isinstance(v, list | tuple):
        return [json_clean(x) for x in v]
    if isinstance(v, np.ndarray):
        return json_clean(v.tolist())
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


def open_set(capture_set: str | Path | CaptureSet) -> tuple[CaptureSet, Rig]:
    """The capture set (loaded and validated when a path is given) and its calibration's rig."""
    cs = capture_set if isinstance(capture_set, CaptureSet) else load_capture_set(capture_set)
    return cs, load_calibration(cs.calibration_path()).rig


class OpenedSet(NamedTuple):
    """A capture set opened for a canonical-mode analysis (:func:`open_canonical`)."""

    #: ``time.perf_counter()`` at the start, for :func:`seconds_since`.
    t0: float
    #: The capture set, loaded and validated.
    cs: CaptureSet
    #: Its calibration's rig.
    rig: Rig
    #: The rig's ``canonical`` rectification.
    rect: Rectification


def open_canonical(capture_set: str | Path | CaptureSet) -> OpenedSet:
    """Every canonical-mode analysis's prologue: the clock at the start (``time.perf_counter``,
    for :func:`seconds_since`), the set and its rig (:func:`open_set`), and the rig's
    ``canonical`` rectification."""
    t0 = time.perf_counter()
    cs, rig = open_set(capture_set)
    return OpenedSet(t0, cs, rig, Rectification.from_rig(rig, "canonical"))


class VerificationSet(NamedTuple):
    """A capture set opened for an analysis of its 'verification' captures in every
    rectification mode (:func:`open_verification`)."""

    #: ``time.perf_counter()`` at the start, for :func:`seconds_since`.
    t0: float
    #: The capture set, loaded and validated.
    cs: CaptureSet
    #: Its calibration's rig.
    rig: Rig
    #: Its 'verification' captures (at least one).
    caps: list[CaptureEntry]


def open_verification(
    capture_set: str | Path | CaptureSet, analysis: str, needs: str
) -> VerificationSet:
    """The prologue of an analysis over a set's 'verification' captures: the clock at the start,
    the set and its rig (:func:`open_set`), and its 'verification' captures (InputError naming
    what ``analysis`` ``needs`` when there are none, :func:`captures_of_kind`)."""
    t0 = time.perf_counter()
    cs, rig = open_set(capture_set)
    return VerificationSet(t0, cs, rig, captures_of_kind(cs, "verification", analysis, needs))


_RAISES = """

    Raises
    ------
    InputError
        An invalid set, or one {lacking}.
    """

#: An analysis body: the opened set (``S``), then its own keyword arguments.
Body = Callable[Concatenate[S, P], T]
#: The public analysis: a capture-set folder or :class:`CaptureSet`, then the same arguments.
Analysis = Callable[Concatenate[str | Path | CaptureSet, P], T]


def _opened_by(
    open_: Callable[[str | Path | CaptureSet], S], lacking: str
) -> Callable[[Body[S, P, T]], Analysis[P, T]]:
    """Decorator: the public ``analyze_*(capture_set, ...)`` from its body ``analyze_*(opened,
    ...)``: it opens ``capture_set`` with ``open_`` and passes the body's other arguments on;
    help() shows ``capture_set`` first, and the docstring is the body's with the shared Raises
    section (an invalid set, or one ``lacking``)."""

    def wrap(body: Body[S, P, T]) -> Analysis[P, T]:
        @functools.wraps(body)
        def analyze(
            capture_set: str | Path | CaptureSet, /, *args: P.args, **kwargs: P.kwargs
        ) -> T:
            return body(open_(capture_set), *args, **kwargs)

        analyze.__doc__ = (body.__doc__ or "").rstrip() + _RAISES.format(lacking=lacking)
        sig = inspect.signature(body)  # help() shows capture_set, not the body's opened set
        first, *rest = sig.parameters.values()
        analyze.__signature__ = sig.replace(  # type: ignore[attr-defined]
            parameters=[first.replace(name="capture_set", annotation="str | Path | CaptureSet",
                                      kind=inspect.Parameter.POSITIONAL_ONLY), *rest]
        )
        return analyze

    return wrap


def canonical_analysis(lacking: str) -> Callable[[Body[OpenedSet, P, T]], Analysis[P, T]]:
    """Decorator: the public ``analyze_*(capture_set, ...)`` of a canonical-mode analysis from
    its body ``analyze_*(opened, ...)``, which takes the set :func:`open_canonical` opened.

    The public function opens ``capture_set`` (a folder, or a loaded :class:`CaptureSet`) and
    passes the body's other arguments on; its docstring is the body's with the Raises section
    every analysis shares: an invalid set, or one ``lacking`` (e.g. "without a refocus stack
    of verification captures"), raises :class:`~phonestereo.errors.InputError`.
    """
    return _opened_by(open_canonical, lacking)


def verification_analysis(
    analysis: str, needs: str
) -> Callable[[Body[VerificationSet, P, T]], Analysis[P, T]]:
    """Decorator like :func:`canonical_analysis` for an analysis of a set's 'verification'
    captures in every rectification mode: the body takes the :class:`VerificationSet`
    :func:`open_verification` opened; a set without 'verification' captures raises
    :class:`~phonestereo.errors.InputError` naming what ``analysis`` ``needs``."""
    return _opened_by(
        lambda capture_set: open_verification(capture_set, analysis, needs),
        "without 'verification' captures",
    )


def seconds_since(t0: float) -> float:
    """Wall time since ``t0`` (``time.perf_counter``), seconds rounded to 0.01: a table's
    ``seconds``."""
    return round(time.perf_counter() - t0, 2)


def captures_of_kind(cs: CaptureSet, kind: str, analysis: str, needs: str) -> list[CaptureEntry]:
    """The captures of ``kind``; InputError naming what ``analysis`` ``needs`` when none."""
    caps = [c for c in cs.captures() if c.kind == kind]
    if not caps:
        raise InputError(
            f"the {analysis} analysis needs {needs}; "
            f"{cs.root} has {len(cs.captures())} capture(s), none of kind '{kind}'"
        )
    return caps


def write_output(
    name: str,
    table: dict[str, Any],
    figures: Sequence[Path],
    summary: tuple[str, ...],
    out_dir: Path,
) -> AnalysisOutput:
    """Write ``table`` (cleaned by :func:`json_clean`) as ``<name>.json`` (``-`` → ``_``) into
    ``out_dir``; the :class:`AnalysisOutput` holding it, the figures and the JSON file."""
    clean = json_clean(table)
    path = out_dir / f"{name.replace('-', '_')}.json"
    path.write_text(json.dumps(clean, indent=1, allow_nan=False) + "\n")
    return AnalysisOutput(
        name, bool(table["ok"]), table["reason"], summary, clean, (*figures, path)
    )


#: Fewest attempts that make a refocus stack.
MIN_ATTEMPTS = 2


def refocus_stacks(cs: CaptureSet, analysis: str, what: str) -> dict[str, list[CaptureEntry]]:
    """The refocus stacks of a set: focus group → its 'verification' captures ordered by
    attempt (then time), for every group of >= :data:`MIN_ATTEMPTS`; InputError naming what
    ``analysis`` needs (``what``: the chart and how it was shot) when there is none."""
    groups: dict[str, list[CaptureEntry]] = {}
    for c in cs.captures():
        if c.kind == "verification" and c.focus_group is not None:
            groups.setdefault(c.focus_group, []).append(c)
    stacks = {k: sorted(v, key=lambda c: (c.focus_attempt or 0, c.time_s or 0.0))
              for k, v in groups.items() if len(v) >= MIN_ATTEMPTS}
    if not stacks:
        raise InputError(
            f"the {analysis} analysis needs a refocus stack: >= {MIN_ATTEMPTS} 'verification' "
            f"captures of {what} sharing a focus_group (one per focus_attempt), e.g. "
            f"`phonestereo simulate refocus`; {cs.root} has none with >= {MIN_ATTEMPTS} attempts"
        )
    return stacks


def measure_each(
    caps: Sequence[CaptureEntry], measure: Callable[[CaptureEntry], T], progress: Progress | None
) -> list[T]:
    """``measure`` of every capture in order, calling ``progress(done, total, id)`` after each."""
    out = []
    for i, c in enumerate(caps):
        out.append(measure(c))
        if progress is not None:
            progress(i + 1, len(caps), c.id)
    return out


def run_table(
    name: str,
    analyze: Callable[..., dict[str, Any]],
    figures: Callable[[dict[str, Any], Path], list[Path]],
    summary: Callable[[dict[str, Any]], tuple[str, ...]],
    capture_set: Path,
    out_dir: Path,
    progress: Progress | None,
) -> AnalysisOutput:
    """A registry entry's work: ``analyze`` the set, then when the table is ok draw the
    ``figures`` and ``summary`` it, otherwise a one-line summary with the reason; write
    ``<name>.json`` (:func:`write_output`)."""
    tb = analyze(capture_set, progress=progress)
    if not tb["ok"]:
        return write_output(name, tb, [], (f"{name}: no result: {tb['reason']}",), out_dir)
    return write_output(name, tb, figures(tb, out_dir), summary(tb), out_dir)


__all__ = [
    "MIN_ATTEMPTS",
    "OpenedSet",
    "VerificationSet",
    "canonical_analysis",
    "captures_of_kind",
    "image_axes",
    "json_clean",
    "label_axes",
    "map_panel",
    "measure_each",
    "open_canonical",
    "open_set",
    "open_verification",
    "refocus_stacks",
    "run_table",
    "save_figure",
    "seconds_since",
    "verification_analysis",
    "write_output",
]
