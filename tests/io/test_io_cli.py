"""`phonestereo check-set` and `convert-calibration` (cli/io_commands.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from phonestereo.cli import io_commands  # noqa: F401  (registers the commands)
from phonestereo.cli.app import app
from phonestereo.geometry import Camera, Rig, Transform, make_lens
from phonestereo.io import (
    Calibration,
    CaptureEntry,
    Manifest,
    load_calibration,
    save_calibration,
    write_image,
    write_manifest,
)


def _cal() -> Calibration:
    wide = Camera((64, 48), 50.0, 50.0, 31.5, 23.5, make_lens("opencv5", (-0.05, 0, 0, 0, 0)))
    tele = Camera((64, 48), 150.0, 150.0, 31.5, 23.5)
    return Calibration(Rig(wide, tele, Transform.from_rotvec([0, 0, 0], [0, -0.012, 0.0015])))


def _set(tmp_path: Path) -> Path:
    entries = [
        CaptureEntry(
            id=f"v{i}",
            wide=f"v{i}_w.png",
            tele=f"v{i}_t.png",
            time_s=200.0 + i,
            orientation="landscape",
            kind="verification",
            focus_group="g1",
            focus_attempt=i,
        )
        for i in range(2)
    ]
    write_manifest(tmp_path, Manifest(captures=entries))
    for e in entries:
        write_image(tmp_path / e.wide, np.zeros((48, 64), np.uint8))
        write_image(tmp_path / e.tele, np.zeros((48, 64), np.uint8))
    save_calibration(tmp_path / "calibration.json", _cal())
    return tmp_path


def test_check_set_ok_and_json(tmp_path: Path) -> None:
    root = _set(tmp_path)
    res = CliRunner().invoke(app, ["check-set", str(root), "--decode"])
    assert res.exit_code == 0, res.output
    assert "ok: 2 captures" in res.output and "baseline 12.09 mm" in res.output
    res = CliRunner().invoke(app, ["check-set", str(root), "--json"])
    data = json.loads(res.output)
    assert data["kinds"] == {"verification": 2} and data["focus_groups"] == ["g1"]
    assert data["calibration"]["zoom"] == 3.0


def test_check_set_reports_errors(tmp_path: Path) -> None:
    root = _set(tmp_path)
    write_image(root / "v1_t.png", np.zeros((10, 10), np.uint8))
    res = CliRunner().invoke(app, ["check-set", str(root), "--decode"])
    assert res.exit_code == 2
    assert "capture 'v1' tele image" in res.output and "is 10x10" in res.output
    (root / "v0_w.png").unlink()
    res = CliRunner().invoke(app, ["check-set", str(root)])
    assert res.exit_code == 2 and "capture 'v0' field 'wide': image file not found" in res.output


def test_convert_json_yaml_json(tmp_path: Path) -> None:
    src = save_calibration(tmp_path / "c.json", _cal())
    res = CliRunner().invoke(app, ["convert-calibration", str(src), str(tmp_path / "c.yml")])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(
        app, ["convert-calibration", str(tmp_path / "c.yml"), str(tmp_path / "back.json")]
    )
    assert res.exit_code == 0, res.output
    back = load_calibration(tmp_path / "back.json")
    assert back.rig.tele == _cal().rig.tele
    res = CliRunner().invoke(app, ["convert-calibration", str(tmp_path / "none.yml"), "x.json"])
    assert res.exit_code == 2 and "not found" in res.output


def test_messages_with_brackets_survive_rich(tmp_path: Path) -> None:
    root = _set(tmp_path)
    data = json.loads((root / "manifest.json").read_text())
    data["captures"][0]["roi"] = [0, 0, 0, 5]
    (root / "manifest.json").write_text(json.dumps(data))
    res = CliRunner().invoke(app, ["check-set", str(root)])
    assert res.exit_code == 2 and "must be [x, y, w, h] with w, h > 0" in res.output
