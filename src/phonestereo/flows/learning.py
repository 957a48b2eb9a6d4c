"""The learning phase (thesis §4.1, Fig. 4-3 / 4-4): face captures → observations in the store.

Blocks per face capture, in order: **gates** (heated, fixed focus, orientation;
:mod:`~phonestereo.flows.gates`) → **focus calibration** of its refocus stack (Fig. 4-1,
:mod:`~phonestereo.flows.focus_stack`) → **landmarks** in both cameras → **depth from IPD**
(eq. 11) → **landmark disparity** (:func:`~phonestereo.learning.learn.learn_capture`) →
**W-T scale** over everything the tele sees (§3.5.1, the same block as the application phase,
so learned and applied disparities share one convention) → with ``radial_residual`` on, the
**residual radial distortion** fitted to that view's non-disparity error (§3.2,
:mod:`~phonestereo.fixes.radial_residual`) → **observations into the fix
store**, one transaction per capture, under the store's context for this calibration and
flow configuration (:mod:`~phonestereo.learning.store_contexts`) and keyed by the capture
set's fingerprint. Captures that do not pass are skipped with the reason; those whose faces
missed the IPD's disparity gate are tried once more about the corrections the others taught
(:func:`run`).

This is the only way observations are made (``learn``, ``batch learn`` and ``evaluate``
alike; ``tests/test_architecture.py`` fails if another module writes to the store). The
face depths come from an :class:`IpdMode`: a face chart of known IPD (all faces on one
plane) or real faces of unknown IPD (the population prior, each head on its own).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from phonestereo.errors import InputError
from phonestereo.features.landmarks import LandmarkBackend
from phonestereo.fixes.distortion import RadialResidualFix
from phonestereo.fixes.radial_residual import fit_capture_radial, radial_shift, wide_center_px
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.face_backends import CachedBackend, PairBackend, default_backend
from phonestereo.flows.face_wt import settle, start_wt
from phonestereo.flows.focus_stack import FocusCorrection, focus_calibration
from phonestereo.flows.gates import Gate, capture_gates, first_failed
from phonestereo.flows.roi_config import centred_rows, reaching
from phonestereo.flows.roi_disparity import RoiMeasurement, reference_rectification
from phonestereo.geometry import Rig
from phonestereo.io import Calibration, CaptureEntry, CaptureSet, read_gray
from phonestereo.io.fingerprint import capture_set_fingerprint
from phonestereo.learning.chart_pitch import CHART_PITCH_M
from phonestereo.learning.ipd import IpdPrior
from phonestereo.learning.learn import Progress, learn_capture
from phonestereo.learning.observation import Observation, typical_correction_px
from phonestereo.learning.provenance import StoreContext
from phonestereo.learning.store import FixStore
from phonestereo.rectification import Rectification


@dataclass(frozen=True)
class IpdMode:
    """Where the faces' depths come from (thesis §3.6, eq. 11)."""

    #: A printed face chart (every face the same known IPD, on one plane), or real faces of unknown
    #: IPD (the prior's mean IPD, each head's own yaw).
    kind: Literal["chart", "population"]
    #: The IPD used, metres.
    ipd_m: float
    #: A chart's eye-midpoint grid pitch, metres (:mod:`~phonestereo.learning.chart_pitch`);
    #: None: the IPDs alone scale its plane.
    pitch_m: float | None = None

    @classmethod
    def chart(cls, ipd_mm: float = 63.0, pitch_mm: float = 1000 * CHART_PITCH_M) -> IpdMode:
        """A face chart printed with ``ipd_mm`` (an adult IPD, 30–100 mm) and its faces' eye
        midpoints on a grid of ``pitch_mm`` (the shipped chart's 325 mm; 0: not used).

        Raises
        ------
        InputError
            An IPD outside 30–100 mm, or a pitch that is neither 0 nor longer than 2 IPDs.
        """
        if not 30.0 < float(ipd_mm) < 100.0:
            raise InputError(
                f"--ipd-mm must be an adult IPD in millimetres (30–100), got {ipd_mm}"
            )
        if not (float(pitch_mm) == 0.0 or 2 * float(ipd_mm) < float(pitch_mm) < 5000.0):
            raise InputError(
                f"--face-pitch-mm must be 0 (off) or the chart's cell in millimetres (longer "
                f"than two IPDs, < 5000), got {pitch_mm}"
            )
        pitch = float(pitch_mm) / 1000.0 if float(pitch_mm) > 0 else None
        return cls("chart", float(ipd_mm) / 1000.0, pitch)

    @classmethod
    def population(cls, prior: IpdPrior | None = None) -> IpdMode:
        """Real faces: the mean IPD of ``prior`` (default the thesis's §3.6 sexes prior)."""
        return cls("population", (prior or IpdPrior.population()).mean_m)

    @property
    def source(self) -> str:
        """The observations' ``source``: ``"face-chart"`` or ``"population"``."""
        return "face-chart" if self.kind == "chart" else "population"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        pitch = None if self.pitch_m is None else round(1000 * self.pitch_m, 4)
        return {"kind": self.kind, "ipd_mm": round(1000 * self.ipd_m, 4), "pitch_mm": pitch}


def store_context(config: FlowConfig, rig: Rig) -> StoreContext:
    """The fix-store context of learning or applying on ``rig`` under ``config``."""
    return StoreContext.build(rig, config.mode, config.context_dict())


@dataclass(frozen=True)
class CaptureLearning:
    """What one face capture gave: observations, or the gate/reason it was skipped."""

    capture_id: str
    observations: tuple[Observation, ...]
    gate: str = ""
    reason: str = ""
    stages: dict[str, Any] = field(default_factory=dict)
    gates: tuple[Gate, ...] = ()
    seconds: float = 0.0
    #: The capture's residual radial distortion (``FlowConfig.radial_residual``), or None.
    radial: RadialResidualFix | None = None

    @property
    def ok(self) -> bool:
        """True when at least one observation was learned."""
        return bool(self.observations)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "capture_id": self.capture_id, "n_observations": len(self.observations),
            "gate": self.gate, "reason": self.reason, "stages": self.stages,
            "gates": [g.to_dict() for g in self.gates], "seconds": round(self.seconds, 4),
        }


@dataclass(frozen=True)
class LearningResult:
    """The learning of a capture set."""

    captures: tuple[CaptureLearning, ...]
    n_observations: int
    seconds: float
    ipd: IpdMode = field(default_factory=IpdMode.chart)
    context_id: int | None = None
    set_fingerprint: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "n_captures": len(self.captures), "n_learned": sum(c.ok for c in self.captures),
            "n_observations": self.n_observations, "seconds": round(self.seconds, 3),
            "ipd": self.ipd.to_dict(), "context_id": self.context_id,
            "set_fingerprint": self.set_fingerprint,
            "skipped": [{"capture_id": c.capture_id, "gate": c.gate, "reason": c.reason}
                        for c in self.captures if not c.ok],
        }


def learn_face_capture(
    config: FlowConfig,
    cs: CaptureSet,
    entry: CaptureEntry,
    calibration: Calibration,
    backend: LandmarkBackend,
    *,
    focus: FocusCorrection | None = None,
    ipd: IpdMode | None = None,
    reference: Rectification | None = None,
    d_offset_px: float = 0.0,
) -> CaptureLearning:
    """The learning blocks of one face capture (module docstring); ``d_offset_px``: the
    calibration's known disparity offset, px (the faces are gated about it,
    :func:`~phonestereo.learning.landmark_disparity.landmark_disparity`)."""
    t0 = time.perf_counter()
    gates = capture_gates(entry, warmup_s=config.warmup_s, heating=config.heating_gate)
    bad = first_failed(gates)
    if bad is not None:
        return CaptureLearning(entry.id, (), bad.name, bad.reason, gates=tuple(gates))
    stages: dict[str, Any] = {}
    if d_offset_px > 0:  # far points read d = −offset: the W-T's view is searched there too
        config = replace(config, roi=reaching(config.roi, d_offset_px))
    rig = calibration.rig
    if config.focus_calibration and focus is not None:
        rig = focus.apply(rig)
        stages["focus_fix"] = focus.to_dict()
    ref = reference
    if ref is None or ref.mode != config.mode:
        ref = reference_rectification(calibration.rig, config.mode)
    rect = ref if rig is calibration.rig else reference_rectification(rig, config.mode)
    path_w, path_t = cs.image_paths(entry.id)
    imgs = (read_gray(path_w), read_gray(path_t))  # decoded once for both blocks
    # the W-T scale's measurement on a thread of its own while MediaPipe detects (face_wt)
    measure, pending = start_wt(config, rig, imgs, rect)
    try:
        return _learn(config, cs, entry, rect, imgs, backend, ipd, measure, gates, stages, t0,
                      d_offset_px)
    finally:
        settle(pending)


def _learn(
    config: FlowConfig, cs: CaptureSet, entry: CaptureEntry, rect: Rectification,
    imgs: tuple[Any, Any], backend: LandmarkBackend, ipd: IpdMode | None,
    measure: Callable[[], RoiMeasurement] | None, gates: list[Gate], stages: dict[str, Any],
    t0: float, d_offset_px: float = 0.0,
) -> CaptureLearning:
    """:func:`learn_face_capture` after its gates: landmarks, landmark disparity, then the W-T
    scale from ``measure()`` (None: the tele's view is not inside the wide image)."""
    mode = ipd or IpdMode.chart()

    def faces(r: Rectification) -> Any:
        return learn_capture(
            cs, entry.id, r, ipd_m=mode.ipd_m, source=mode.source,
            depth_mode="chart" if mode.kind == "chart" else "face", chart_pitch_m=mode.pitch_m,
            backend=backend, images=imgs, d_offset_px=d_offset_px,
        )

    res = faces(rect)
    m: RoiMeasurement | None = None
    if not res.observations and measure is not None:
        # Faces are paired and searched over rows about e = 0 (max_e_px): a calibration whose
        # rows are off by more (random-3056: 11–12 px after warm-up) loses them all. The W-T
        # measurement's coarse step found the rows; the faces are searched about them.
        m = measure()
        rows = centred_rows(config.roi, float(m.counts.get("coarse_e_px", 0))) if m.ok else 0
        if rows:
            res = faces(rect.with_tele_rows(rows))
            stages["row_offset_px"] = rows
    stages["landmarks"] = {"reason": res.reason, "timing_s": res.timing_s,
                           "wide_faces": 0 if res.disparity is None else res.disparity.n_wide}
    obs = res.observations
    if not obs:
        return CaptureLearning(entry.id, (), "faces", res.reason, stages, tuple(gates),
                               time.perf_counter() - t0)
    radial = None
    if config.wt_scale:
        wt = None
        why = "the tele's view is not inside the wide image"
        if measure is not None:
            m = measure() if m is None else m
            wt = m.wt
            why = m.reason or (wt.reason if wt is not None else "")
        stages["wt_scale"] = None if wt is None else wt.to_dict()
        if wt is None or not wt.ok:
            # Unscaled observations would teach the field the breathing of this one attempt.
            return CaptureLearning(entry.id, (), "wt-scale", f"no W-T scale: {why}", stages,
                                   tuple(gates), time.perf_counter() - t0)
        obs = tuple(
            replace(o, d_measured_px=float(wt.correct_disparity(o.x_px, o.d_measured_px)))
            for o in obs
        )
        if config.radial_residual:  # §3.2: the e of the whole view's matches gives P(r)
            assert m is not None  # (wt came from it)
            radial = fit_capture_radial(m.xy, m.e, wide_center_px(rect))
            stages["radial_residual"] = None if radial is None else radial.to_dict()
            if radial is not None:
                dx = radial_shift(radial, np.array([[o.x_px, o.y_px] for o in obs]))[:, 0]
                obs = tuple(  # radial_px: the correction re-refers it to the pooled fit
                    replace(o, d_measured_px=o.d_measured_px - float(v), radial_px=float(v))
                    for o, v in zip(obs, dx, strict=True)
                )
    if config.orientation_buckets is False:
        obs = tuple(replace(o, orientation="all") for o in obs)
    return CaptureLearning(entry.id, obs, "", "", stages, tuple(gates), time.perf_counter() - t0,
                           radial)


def stack_corrections(
    config: FlowConfig, cs: CaptureSet, entries: list[CaptureEntry], calibration: Calibration
) -> dict[str, FocusCorrection]:
    """Focus calibration (Fig. 4-1) of every refocus stack among ``entries``: capture id →
    its correction (stacks of one attempt get none)."""
    if not config.focus_calibration:
        return {}
    groups: dict[str, list[CaptureEntry]] = {}
    for e in entries:
        if e.focus_group:
            groups.setdefault(e.focus_group, []).append(e)
    out: dict[str, FocusCorrection] = {}
    for members in groups.values():
        if len(members) < 2:
            continue
        members = sorted(members, key=lambda e: (e.focus_attempt or 0, e.time_s or 0.0))
        paths = [cs.image_paths(e.id) for e in members]
        wide = [read_gray(p[0]) for p in paths]
        tele = [read_gray(p[1]) for p in paths]
        box = members[0].roi
        corr = focus_calibration(calibration.rig, wide, tele, wide_box=box)
        out.update({e.id: c for e, c in zip(members, corr, strict=True)})
    return out


#: A learning run retries the face captures whose faces found no partner with the gates
#: centred on the typical correction of those it learned, when that is at least this far from 0
#: (px): half the gate's fixed part (``d_tol_px`` 4 px); nearer, the gates hold it already.
RETRY_OFFSET_PX = 2.0


def _gated_faces(r: CaptureLearning) -> bool:
    """The wide found faces, yet none was measured in the tele."""
    return r.gate == "faces" and r.stages.get("landmarks", {}).get("wide_faces", 0) > 0


def run(
    config: FlowConfig,
    cs: CaptureSet,
    calibration: Calibration,
    store: FixStore | None,
    *,
    backend: LandmarkBackend | None = None,
    ipd: IpdMode | None = None,
    new_context: bool = False,
    progress: Progress | None = None,
) -> LearningResult:
    """Learn every face capture of ``cs`` (module docstring); observations go into ``store``
    (one transaction per capture) when one is given.

    Parameters
    ----------
    config : FlowConfig
    cs : CaptureSet
    calibration : Calibration
        The calibration learned on (its rig is part of the store context).
    store : FixStore or None
        None: the observations are only returned.
    backend : LandmarkBackend, optional
        Default :func:`default_backend`.
    ipd : IpdMode, optional
        Default a face chart of 63 mm.
    new_context : bool
        Start a new context in ``store`` when it holds observations learned under another
        calibration or configuration (else that is refused).
    progress : callable, optional
        ``progress(done, total, capture_id)`` after each face capture.

    Raises
    ------
    InputError
        No face captures.
    ContextError
        ``store`` was learned under another context and ``new_context`` is False; raised
        before anything is learned or written.
    """
    t0 = time.perf_counter()
    mode = ipd or IpdMode.chart()
    faces = [c for c in cs.captures() if c.kind == "face"]
    if not faces:
        raise InputError(
            f"capture set {cs.root} has no captures of kind 'face'; learning needs face captures"
        )
    context_id, fingerprint = None, ""
    if store is not None:
        ctx = store_context(config, calibration.rig)
        context_id = store.context_for_learning(ctx, new=new_context)
        fingerprint = capture_set_fingerprint(cs)
    det = backend if backend is not None else default_backend()
    corr = stack_corrections(config, cs, faces, calibration)
    ref = reference_rectification(calibration.rig, config.mode)

    def learn(entry: CaptureEntry, offset: float = 0.0) -> CaptureLearning:
        r = learn_face_capture(config, cs, entry, calibration, det, focus=corr.get(entry.id),
                               ipd=mode, reference=ref, d_offset_px=offset)
        if r.ok and store is not None:
            store.add_capture(entry.id, list(r.observations), context_id=context_id,
                              set_fingerprint=fingerprint, set_folder=str(cs.root.resolve()),
                              radial=r.radial)
        return r

    out = []
    for k, entry in enumerate(faces):
        out.append(learn(entry))
        if progress is not None:
            progress(k + 1, len(faces), entry.id)
    # Faces are gated about the disparity their IPD predicts; a calibration off by more than
    # the gate (random-3004: +7.5 px) loses its far faces. The captures learned say by how much.
    offset = typical_correction_px([o for r in out for o in r.observations])
    if abs(offset) >= RETRY_OFFSET_PX:
        out = [learn(e, offset) if _gated_faces(r) else r for e, r in zip(faces, out, strict=True)]
    n_obs = sum(len(r.observations) for r in out if r.ok)
    seconds = time.perf_counter() - t0
    return LearningResult(tuple(out), n_obs, seconds, mode, context_id, fingerprint)


__all__ = [
    "CachedBackend",
    "CaptureLearning",
    "IpdMode",
    "LearningResult",
    "PairBackend",
    "default_backend",
    "learn_face_capture",
    "run",
    "stack_corrections",
    "store_context",
]
