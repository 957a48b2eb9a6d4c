"""`phonestereo faces`: listing, JSON, overlay, OpenFace CSV input and clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import phonestereo.cli.faces  # noqa: F401  (registers the command; the lead wires cli/__init__)
from phonestereo.cli.app import app
from phonestereo.features.landmarks.openface import openface_columns

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "faces"
needs_data = pytest.mark.skipif(not DATA.exists(), reason="shared/data not beside the clone")


def _run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(app, list(args))
    return res.exit_code, res.output


@needs_data
def test_faces_json_and_overlay(tmp_path: Path) -> None:
    img = tmp_path / "portrait.jpg"
    cv2.imwrite(str(img), cv2.resize(cv2.imread(str(DATA / "interfaces_035.jpg")), (500, 500)))
    code, out = _run("faces", str(img), "--json", "--overlay", str(tmp_path / "ov.png"))
    assert code == 0, out
    doc = json.loads(out.strip().splitlines()[-1])
    assert doc["found"] and doc["n_faces"] == 1 and doc["backend"] == "mediapipe"
    face = doc["faces"][0]
    assert 90 < face["ipd_px"] < 110  # 1000-px portrait IPD 201 px, halved
    assert face["pupils_px"][0][0] < face["pupils_px"][1][0] and abs(face["yaw_deg"]) < 10
    overlay = cv2.imread(str(tmp_path / "ov.png"))
    assert overlay.shape == (500, 500, 3)
    code, text = _run("faces", str(img))
    assert code == 0 and "1 face(s)" in text and "ipd" in text and "yaw" in text
    rolled = tmp_path / "rolled.jpg"
    cv2.imwrite(str(rolled), cv2.rotate(cv2.imread(str(img)), cv2.ROTATE_90_CLOCKWISE))
    assert _run("faces", str(rolled))[0] == 1
    code, text = _run("faces", str(rolled), "--any-orientation")
    assert code == 0 and "1 face(s)" in text


def test_faces_without_a_face_exits_1_with_the_reason(tmp_path: Path) -> None:
    img = tmp_path / "grey.png"
    cv2.imwrite(str(img), np.full((300, 400), 128, np.uint8))
    code, out = _run("faces", str(img), "--overlay", str(tmp_path / "ov.png"))
    assert code == 1 and "no face found" in out
    assert (tmp_path / "ov.png").exists()


def test_faces_bad_input_exits_2(tmp_path: Path) -> None:
    code, out = _run("faces", str(tmp_path / "missing.png"))
    assert code == 2 and "not found" in " ".join(out.split())
    (tmp_path / "bad.png").write_bytes(b"not an image")
    code, out = _run("faces", str(tmp_path / "bad.png"))
    assert code == 2 and "cannot decode" in " ".join(out.split())


def test_faces_from_an_openface_csv(tmp_path: Path) -> None:
    img = tmp_path / "shot.png"
    cv2.imwrite(str(img), np.zeros((480, 640), np.uint8))
    lm = np.column_stack([np.linspace(250, 390, 68), np.full(68, 240.0)])
    lm[36:42] = [290.0, 230.0]
    lm[42:48] = [350.0, 230.0]
    csv = tmp_path / "shot.csv"
    pd.DataFrame([{"face": 0, "confidence": 0.9} | openface_columns(lm)]).to_csv(csv, index=False)
    code, out = _run("faces", str(img), "--openface-csv", str(csv), "--json")
    assert code == 0, out
    doc = json.loads(out.strip().splitlines()[-1])
    assert doc["backend"] == "openface" and doc["faces"][0]["ipd_px"] == 60.0
    assert any("-pose" in n for n in doc["notes"])
    bad = tmp_path / "bad.csv"
    pd.DataFrame([{"face": 0, "x_0": 1.0}]).to_csv(bad, index=False)
    code, out = _run("faces", str(img), "--openface-csv", str(bad))
    assert code == 2 and "-2Dfp" in " ".join(out.split())
