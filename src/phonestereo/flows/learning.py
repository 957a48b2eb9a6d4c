"""The learning phase (thesis §4.1, Fig. 4-3 / 4-4): face captures → observations in the store.

Blocks per face capture, in order: **gates** (heated, fixed focus, orientation;
:mod:`~phonestereo.flows.gates`) → **focus calibration** of its refocus stack (Fig. 4-1,
:mod:`~phonestereo.flows.focus_stack`) → **landmarks** in both cameras → **depth from IPD**
(eq. 11) → **landmark disparity** (:func:`~phonestereo.learning.learn.learn_capture`) →
**W-T scale** over the face chart's texture (§3.5.1, the same block as the application phase,
so learned and applied disparities share one convention) → **observations into the fix
store**, one transaction per capture. Captures that do not pass are skipped with the reason.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.features.landmarks import LandmarkBackend, MediaPipeBackend
from phonestereo.features.landmarks.base import FaceResult, TeleGuide, guided_pair
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.focus_stack import FocusCorrection, focus_calibration
from phonestereo.flows.gates import Gate, capture_gates, first_failed
from phonestereo.flows.roi_disparity import measure_roi, reference_rectification, tele_view_box
from phonestereo.io import Calibration, CaptureEntry, CaptureSet, read_gray
from phonestereo.learning.learn import learn_capture
from phonestereo.learning.observation import Observation
from phonestereo.learning.store import FixStore
from phonestereo.rectification import Rectification

Progress = Callable[[int, int, str], None]


class CachedBackend(LandmarkBackend):
    """A landmark backend that remembers its answers per image content (for ablations that
    re-learn the same captures under other switches: landmarks do not depend on them)."""

    name = "cached"

    def __init__(self, backend: LandmarkBackend) -> None:
        self.backend = backend
        self._cache: dict[str, FaceResult] = {}
        self._pairs: dict[str, tuple[FaceResult, FaceResult]] = {}

    @staticmethod
    def _key(image: Any) -> str:
        a = np.ascontiguousarray(np.asarray(image))
        return f"{a.shape}{a.dtype}" + hashlib.blake2b(a.data, digest_size=16).hexdigest()

    def detect(self, image: Any) -> FaceResult:
        key = self._key(image)
        if key not in self._cache:
            self._cache[key] = self.backend.detect(image)
        return self._cache[key]

    def detect_many(self, images: Iterable[Any]) -> list[FaceResult]:
        return [self.detect(im) for im in images]

    def detect_pair(
        self, wide: Any, tele: Any, guide: TeleGuide | None = None
    ) -> tuple[FaceResult, FaceResult]:
        key = self._key(wide) + self._key(tele) + ("" if guide is None else guide.key)
        if key not in self._pairs:
            self._pairs[key] = self.backend.detect_pair(wide, tele, guide)
        return self._pairs[key]


class PairBackend(LandmarkBackend):
    """One backend for the wide image and another for the tele of a ``detect_many([wide,
    tele])`` or :meth:`detect_pair` call.

    With a guide (:class:`~phonestereo.learning.pair_guide.WideToTeleGuide`) the tele is
    not searched: it is measured only where the wide's faces map to.
    """

    name = "pair"

    def __init__(self, wide: LandmarkBackend, tele: LandmarkBackend) -> None:
        self.wide = wide
        self.tele = tele

    def detect(self, image: Any) -> FaceResult:
        return self.wide.detect(image)

    def detect_many(self, images: Iterable[Any]) -> list[FaceResult]:
        ims = list(images)
        if len(ims) != 2:
            return self.wide.detect_many(ims)
        return [self.wide.detect(ims[0]), self.tele.detect(ims[1])]

    def detect_pair(
        self, wide: Any, tele: Any, guide: TeleGuide | None = None
    ) -> tuple[FaceResult, FaceResult]:
        return guided_pair(self.wide, self.tele, wide, tele, guide)


def default_backend() -> LandmarkBackend:
    """MediaPipe for the learning flow (measured in ``benchmarks/bench_flows.py``).

    The wide is searched with two tile levels (13 detector runs instead of 42, the same faces
    found on the bench sets) and without mirror averaging (no loss of depth accuracy on the
    bench: the chart plane averages the faces' IPDs); the tele, guided by the wide's faces,
    is only measured. The tele's faces are three times larger and only pair the faces and
    start the disparity search (the eye windows refine it), so it needs no mirror averaging.
    """
    return PairBackend(
        MediaPipeBackend(mirror_average=False, two_level_tiles=(0.35, 0.08)),
        MediaPipeBackend(min_tile_px=1000, mirror_average=False),
    )


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
        }  # fmt: skip


@dataclass(frozen=True)
class LearningResult:
    """The learning of a capture set."""

    captures: tuple[CaptureLearning, ...]
    n_observations: int
    seconds: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "n_captures": len(self.captures), "n_learned": sum(c.ok for c in self.captures),
            "n_observations": self.n_observations, "seconds": round(self.seconds, 3),
            "skipped": [{"capture_id": c.capture_id, "gate": c.gate, "reason": c.reason}
                        for c in self.captures if not c.ok],
        }  # fmt: skip


def _faces_box(
    ref: Rectification, obs: tuple[Observation, ...], size: tuple[int, int]
) -> tuple[int, int, int, int] | None:
    """The raw-wide box around the learned faces, padded by a third of its size (≥ 80 px),
    inside the tele's view."""
    if not obs:
        return None
    raw = ref.unrectify_wide(np.array([[o.x_px, o.y_px] for o in obs]))
    raw = raw[np.isfinite(raw).all(axis=1)]
    if len(raw) == 0:
        return None
    lo, hi = raw.min(axis=0), raw.max(axis=0)
    pad = np.maximum(80.0, (hi - lo) / 3)
    tx, ty, tw, th = tele_view_box(ref)
    lo = np.maximum(lo - pad, [tx, ty])
    hi = np.minimum(np.minimum(hi + pad, np.array(size) - 1), [tx + tw, ty + th])
    if np.any(hi - lo < 32):
        return None
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])


def learn_face_capture(
    config: FlowConfig,
    cs: CaptureSet,
    entry: CaptureEntry,
    calibration: Calibration,
    backend: LandmarkBackend,
    *,
    focus: FocusCorrection | None = None,
    ipd_m: float = 0.063,
    reference: Rectification | None = None,
) -> CaptureLearning:
    """The learning blocks of one face capture (module docstring)."""
    t0 = time.perf_counter()
    gates = capture_gates(entry, warmup_s=config.warmup_s, heating=config.heating_gate)
    bad = first_failed(gates)
    if bad is not None:
        return CaptureLearning(entry.id, (), bad.name, bad.reason, gates=tuple(gates))
    stages: dict[str, Any] = {}
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
    res = learn_capture(cs, entry.id, rect, ipd_m=ipd_m, backend=backend, images=imgs)
    stages["landmarks"] = {"reason": res.reason, "timing_s": res.timing_s}
    obs = res.observations
    if not obs:
        return CaptureLearning(entry.id, (), "faces", res.reason, stages, tuple(gates),
                               time.perf_counter() - t0)  # fmt: skip
    if config.wt_scale:
        box = _faces_box(rect, obs, rig.wide.size)
        wt = None
        why = "the faces are not inside the tele's view"
        if box is not None:
            m = measure_roi(
                rig, imgs[0], imgs[1], box, replace(config.roi, expand=1.0, coarse_expand=1.0), rect
            )
            wt = m.wt
            why = m.reason or (wt.reason if wt is not None else "")
        stages["wt_scale"] = None if wt is None else wt.to_dict()
        if wt is None or not wt.ok:
            # Unscaled observations would teach the field the breathing of this one attempt.
            return CaptureLearning(entry.id, (), "wt-scale", f"no W-T scale: {why}", stages,
                                   tuple(gates), time.perf_counter() - t0)  # fmt: skip
        obs = tuple(
            replace(o, d_measured_px=float(wt.correct_disparity(o.x_px, o.d_measured_px)))
            for o in obs
        )
    if config.orientation_buckets is False:
        obs = tuple(replace(o, orientation="all") for o in obs)
    return CaptureLearning(entry.id, obs, "", "", stages, tuple(gates), time.perf_counter() - t0)


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


def run(
    config: FlowConfig,
    cs: CaptureSet,
    calibration: Calibration,
    store: FixStore | None,
    *,
    backend: LandmarkBackend | None = None,
    ipd_mm: float = 63.0,
    progress: Progress | None = None,
) -> LearningResult:
    """Learn every face capture of ``cs`` (module docstring); observations go into ``store``
    (one transaction per capture) when one is given.

    Raises
    ------
    InputError
        No face captures, or an IPD outside 30–100 mm.
    """
    t0 = time.perf_counter()
    if not 30.0 < float(ipd_mm) < 100.0:
        raise InputError(f"IPD must be an adult IPD in millimetres (30–100), got {ipd_mm}")
    faces = [c for c in cs.captures() if c.kind == "face"]
    if not faces:
        raise InputError(
            f"capture set {cs.root} has no captures of kind 'face'; learning needs face captures"
        )
    det = backend if backend is not None else default_backend()
    corr = stack_corrections(config, cs, faces, calibration)
    ref = reference_rectification(calibration.rig, config.mode)
    out, n_obs = [], 0
    for k, entry in enumerate(faces):
        r = learn_face_capture(
            config,
            cs,
            entry,
            calibration,
            det,
            focus=corr.get(entry.id),
            ipd_m=ipd_mm / 1000,
            reference=ref,
        )
        out.append(r)
        if r.ok and store is not None:
            n_obs += store.add_capture(entry.id, list(r.observations))
        elif r.ok:
            n_obs += len(r.observations)
        if progress is not None:
            progress(k + 1, len(faces), entry.id)
    return LearningResult(tuple(out), n_obs, time.perf_counter() - t0)


__all__ = [
    "CachedBackend",
    "CaptureLearning",
    "LearningResult",
    "PairBackend",
    "default_backend",
    "learn_face_capture",
    "run",
    "stack_corrections",
]
