"""Android importer on bad dumps: every error is typed, names the key and the fix, and nothing
is half-written."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from PIL import Image

from phonestereo.errors import InputError
from phonestereo.io import load_capture_set
from phonestereo.io.importers.android import import_android
from phonestereo.sim.export_android import write_android_dump

Edit = Callable[[dict[str, Any], dict[str, Any], Path], None]


@pytest.fixture(scope="module")
def good_dump(tmp_path_factory: pytest.TempPathFactory, write_sim: Any) -> Path:
    root = tmp_path_factory.mktemp("android_good")
    cal, manifest = write_sim(root / "native", "verification")
    return write_android_dump(root / "android", cal, manifest, root / "native")


def _session_cam(s: dict[str, Any]) -> dict[str, Any]:
    return s["cameras"]["2"]


def _del(key: str) -> Edit:
    return lambda s, c, d: _session_cam(s).pop(key)


def _set(key: str, value: Any) -> Edit:
    return lambda s, c, d: _session_cam(s).__setitem__(key, value)


def _small_tele(s: dict[str, Any], c: dict[str, Any], d: Path) -> None:
    Image.new("L", (1000, 1000)).save(d / c["cameras"]["4"]["image"])


def _no_gravity(s: dict[str, Any], c: dict[str, Any], d: Path) -> None:
    c.pop("accelerometer")


def _no_af_mode(s: dict[str, Any], c: dict[str, Any], d: Path) -> None:
    c["cameras"]["2"].pop("android.control.afMode")


CASES = [
    ("missing key", _del("android.lens.intrinsicCalibration"),
     r"android\.lens\.intrinsicCalibration.*required key is missing"),
    ("wrong length", _set("android.lens.distortion", [0.1, 0.0, 0.0, 0.0]),
     r"android\.lens\.distortion.*needs 5 numbers"),
    ("non-finite", _set("android.lens.poseTranslation", [float("nan"), 0.0, 0.0]),
     r"android\.lens\.poseTranslation.*non-finite"),
    ("UNDEFINED pose reference", _set("android.lens.poseReference", 2),
     r"android\.lens\.poseReference.*UNDEFINED.*phonestereo calibrate"),
    ("unknown pose reference", _set("android.lens.poseReference", 7),
     r"android\.lens\.poseReference.*unknown"),
    ("quaternion in the wrong order", _set("android.lens.poseRotation", [0.0, 0.0, 0.0, 1.0]),
     r"android\.lens\.poseRotation.*sensor\.orientation"),
    ("image size fits neither array nor crop", _small_tele,
     r"key 'image'.*neither the active array.*cropRegion"),
    ("no accelerometer and no label", _no_gravity, r"'accelerometer'.*required"),
    ("missing CaptureResult key", _no_af_mode, r"android\.control\.afMode.*required key"),
]


@pytest.mark.parametrize(("name", "edit", "match"), CASES, ids=[c[0] for c in CASES])
def test_bad_dump_is_refused_naming_the_key(
    good_dump: Path, tmp_path: Path, name: str, edit: Edit, match: str
) -> None:
    dump = tmp_path / "dump"
    shutil.copytree(good_dump, dump)
    session = json.loads((dump / "session.json").read_text())
    first = sorted((dump / "captures").glob("*.json"))[0]
    capture = json.loads(first.read_text())
    edit(session, capture, dump)
    (dump / "session.json").write_text(json.dumps(session))
    first.write_text(json.dumps(capture))
    with pytest.raises(InputError, match=match):
        import_android(dump, tmp_path / "set")
    assert not (tmp_path / "set").exists()  # nothing half-written
    assert not list(tmp_path.glob(".set.importing-*"))


def test_good_dump_imports_and_never_overwrites(good_dump: Path, tmp_path: Path) -> None:
    import_android(good_dump, tmp_path / "set")
    assert len(load_capture_set(tmp_path / "set").captures()) == 4
    with pytest.raises(InputError, match="not an empty folder"):
        import_android(good_dump, tmp_path / "set")


def test_cli_gives_exit_2_with_the_key_and_json_on_success(good_dump: Path, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from phonestereo.cli import app

    dump = tmp_path / "dump"
    shutil.copytree(good_dump, dump)
    session = json.loads((dump / "session.json").read_text())
    session["cameras"]["4"]["android.lens.poseReference"] = 3
    (dump / "session.json").write_text(json.dumps(session))
    r = CliRunner().invoke(app, ["import", "android", str(dump), "--out", str(tmp_path / "bad")])
    assert r.exit_code == 2 and "poseReference" in r.output and "AUTOMOTIVE" in r.output
    r = CliRunner().invoke(app, ["import", "android", str(good_dump), "--out",
                                 str(tmp_path / "set"), "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["captures"] == 4 and out["cameras"] == {"wide": "2", "tele": "4"}
    assert out["calibration"]["zoom"] == pytest.approx(3.054, abs=1e-3)
