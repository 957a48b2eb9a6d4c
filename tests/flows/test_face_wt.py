"""The W-T scale of a face capture measured while its landmarks are detected (flows/face_wt.py).

``learn_face_capture`` starts the W-T scale's ``measure_roi`` on the helper thread before the
landmarks; the observations must be those of measuring after them on one thread, and a capture
that learns nothing must leave no measurement running.
"""

from __future__ import annotations

import json
import threading
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from _support.face_chart import write_face_chart_set
from phonestereo.features._threads import background
from phonestereo.features.landmarks import Face, FaceResult, LandmarkBackend
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.face_wt import settle, start_wt
from phonestereo.flows.learning import learn_face_capture
from phonestereo.flows.roi_disparity import reference_rectification
from phonestereo.io import load_calibration, load_capture_set


class TruthBackend(LandmarkBackend):
    """The simulator's true pupils of the set's one capture (no MediaPipe in fast tests)."""

    name = "truth"

    def __init__(self, folder: Path) -> None:
        cap = json.loads((folder / "ground_truth.json").read_text())["captures"][0]
        kp = cap["objects"][0]["keypoints"]["pupils"]
        self.pair = tuple(self._result(kp[k]) for k in ("wide_px", "tele_px"))

    @staticmethod
    def _result(pts: list[Any]) -> FaceResult:
        faces = []
        for i in range(0, len(pts), 2):
            if None in pts[i] + pts[i + 1]:
                continue
            a = np.array(pts[i : i + 2], dtype=float)
            faces.append(Face(a, a, a, 0.0, 1.0, np.r_[a.min(0) - 30, a.max(0) + 30]))
        return FaceResult(tuple(faces), (2000, 1500), "truth", "" if faces else "no face found")

    def detect(self, image: Any) -> FaceResult:  # pragma: no cover - detect_pair is used
        raise NotImplementedError

    def detect_pair(self, wide: Any, tele: Any, guide: Any = None) -> tuple[FaceResult, ...]:
        return self.pair


@pytest.fixture(scope="module")
def capture_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One face-chart capture at 1.5 m (noise on, seeded)."""
    return write_face_chart_set(tmp_path_factory.mktemp("face_wt_set"), attempts=1)


def _learn(folder: Path, config: FlowConfig) -> Any:
    cs = load_capture_set(folder)
    cal = load_calibration(cs.calibration_path())
    entry = next(c for c in cs.captures() if c.kind == "face")
    return learn_face_capture(config, cs, entry, cal, TruthBackend(folder))


def test_measured_ahead_gives_the_observations_of_one_thread(
    capture_set: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    ahead = _learn(capture_set, FlowConfig())
    monkeypatch.setenv("PHONESTEREO_THREADS", "1")  # measured after the landmarks, here
    here = _learn(capture_set, FlowConfig())
    assert ahead.ok and ahead.stages["wt_scale"] is not None
    assert ahead.observations == here.observations  # every float to the bit
    assert ahead.stages["wt_scale"] == here.stages["wt_scale"]


def test_no_w_t_scale_starts_nothing(capture_set: Path) -> None:
    cs = load_capture_set(capture_set)
    rig = load_calibration(cs.calibration_path()).rig
    off = FlowConfig(wt_scale=False)
    assert start_wt(off, rig, (None, None), reference_rectification(rig, off.mode)) == (None, None)


def test_settle_cancels_a_queued_measurement_and_waits_for_a_running_one() -> None:
    started, release = threading.Event(), threading.Event()

    def running() -> int:
        started.set()
        release.wait(5.0)
        return 1

    first = background(running)
    queued: Future[int] = background(lambda: 2)
    if not started.wait(5.0) or first.done():  # no second core: both ran in line
        pytest.skip("the helper thread is off here")
    settle(queued)
    assert queued.cancelled()
    threading.Timer(0.05, release.set).start()
    settle(first)
    assert first.done() and first.result() == 1
    settle(None)
