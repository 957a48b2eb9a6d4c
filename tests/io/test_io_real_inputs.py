"""Real-phone inputs (issue #17 item 5 and the io/ cases of issue #19's bad-input sweep).

Each test here failed on main before this change (the behaviour it checks was missing).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from phonestereo.cli import io_commands  # noqa: F401  (registers the commands)
from phonestereo.cli.app import app
from phonestereo.errors import InputError
from phonestereo.fixes.orientation import BUCKETS
from phonestereo.fixes.warmup import WarmupGate
from phonestereo.flows.gates import fixed_focus_gate, heated_gate
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.io import (
    Calibration,
    CaptureEntry,
    Manifest,
    calibration_from_dict,
    calibration_to_dict,
    parse_manifest,
    read_gray,
    save_calibration,
    write_image,
    write_manifest,
)
from phonestereo.io.manifest import ORIENTATION_BUCKETS

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
WIDE_ULTRA = DATA / "phone_wide_ultra"


def _run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(app, list(args))
    return res.exit_code, res.output


def _cal(size: tuple[int, int] = (64, 48)) -> Calibration:
    wide = Camera(size, 50.0, 50.0, (size[0] - 1) / 2, (size[1] - 1) / 2)
    tele = Camera(size, 150.0, 150.0, (size[0] - 1) / 2, (size[1] - 1) / 2)
    return Calibration(Rig(wide, tele, Transform.from_rotvec([0, 0, 0], [0, -0.012, 0.0])))


def _set(root: Path, wide: str = "w.png", size: tuple[int, int] = (64, 48)) -> Path:
    entry = CaptureEntry(id="c1", wide=wide, tele="t.png", time_s=200.0,
                         orientation="landscape", kind="scene", focus_mode="manual")
    write_manifest(root, Manifest(captures=[entry]))
    write_image(root / "t.png", np.zeros((48, 64), np.uint8))
    if wide == "w.png":
        write_image(root / "w.png", np.zeros((size[1], size[0]), np.uint8))
    save_calibration(root / "calibration.json", _cal())
    return root


# --- convert-calibration ------------------------------------------------------------------------
@pytest.mark.skipif(not WIDE_ULTRA.exists(), reason="shared/data not beside the clone")
def test_phone_wide_ultra_opencv_files_convert_and_say_r_was_snapped(tmp_path: Path) -> None:
    out = tmp_path / "out.json"
    args = ["convert-calibration", str(WIDE_ULTRA / "intrinsics.yml"), str(out)]
    args += ["--extrinsics", str(WIDE_ULTRA / "extrinsics.yml"), "--first-camera", "tele"]
    args += ["--wide-size", "480x424", "--tele-size", "480x424", "--json"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    cal = json.loads(out.read_text())
    # The values of the files (8 printed decimals): f_x to 1e-3 px, |t| to 1e-3 mm.
    assert cal["tele"]["K"][0][0] == pytest.approx(723.345, abs=1e-3)
    assert cal["wide"]["K"][0][0] == pytest.approx(393.140, abs=1e-3)
    assert doc["baseline_m"] * 1000 == pytest.approx(19.330, abs=1e-3)
    # R printed with 8 decimals is orthonormal to ~1e-8 only; the command says it was snapped.
    assert doc["r_reorthonormalised"] and 1e-10 < doc["r_deviation"] < 1e-6
    assert "replaced by the nearest rotation" in res.stderr
    r = np.array(cal["T_tele_wide"]["R"])
    assert np.abs(r @ r.T - np.eye(3)).max() < 1e-14  # written as an exact rotation


def test_convert_exact_rotation_says_nothing(tmp_path: Path) -> None:
    save_calibration(tmp_path / "c.json", _cal())
    args = ["convert-calibration", str(tmp_path / "c.json"), str(tmp_path / "c.yml"), "--json"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert not json.loads(res.stdout)["r_reorthonormalised"] and res.stderr == ""


def test_convert_refuses_unknown_output_suffix(tmp_path: Path) -> None:
    save_calibration(tmp_path / "c.json", _cal())
    code, out = _run("convert-calibration", str(tmp_path / "c.json"), str(tmp_path / "out.txt"))
    assert code == 2 and "'.txt'" in out and ".json" in out and ".yml" in out
    assert not (tmp_path / "out.txt").exists()


def test_convert_yaml_with_one_element_t_is_a_typed_error(tmp_path: Path) -> None:
    ext = tmp_path / "extrinsics.yml"
    ext.write_text(
        "%YAML:1.0\n---\n"
        "R: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]\n"
        "T: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ 0.01 ]\n"
    )
    intr = tmp_path / "intrinsics.yml"
    intr.write_text(
        "%YAML:1.0\n---\n"
        "M1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 500., 0., 319.5, 0., 500., 239.5, 0., 0., 1. ]\n"
        "D1: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ 0., 0., 0., 0., 0. ]\n"
        "M2: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 1500., 0., 319.5, 0., 1500., 239.5, 0., 0., 1. ]\n"
        "D2: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ 0., 0., 0., 0., 0. ]\n"
    )
    sizes = ["--wide-size", "640x480", "--tele-size", "640x480"]
    code, out = _run("convert-calibration", str(intr), str(tmp_path / "o.json"),
                     "--extrinsics", str(ext), *sizes)
    assert code == 2, out
    assert "extrinsics.yml: field 'T'" in out and "Traceback" not in out
    # Without the sizes the message names the CLI flag, not the Python argument.
    code, out = _run("convert-calibration", str(intr), str(tmp_path / "o.json"))
    assert code == 2 and "--wide-size" in out


def test_null_covariance_and_parameter_names_load() -> None:
    d = calibration_to_dict(_cal())
    for value in (None, "absent"):
        doc = dict(d)
        if value == "absent":
            doc.pop("covariance", None)
            doc.pop("parameter_names", None)
        else:
            doc["covariance"], doc["parameter_names"] = None, None
        cal = calibration_from_dict(json.loads(json.dumps(doc)))
        assert cal.covariance is None and cal.parameter_names == ()


# --- images -------------------------------------------------------------------------------------
def test_read_gray_ignores_exif_orientation(tmp_path: Path) -> None:
    # A landscape sensor image saved with EXIF Orientation 6 ("rotate 90° to view"): the
    # calibration describes the stored grid, so it must come back 80 wide, 60 high.
    img = Image.new("L", (80, 60), 0)
    exif = Image.Exif()
    exif[0x0112] = 6
    img.save(tmp_path / "p.jpg", exif=exif.tobytes())
    assert read_gray(tmp_path / "p.jpg").shape == (60, 80)


def test_check_set_names_a_portrait_jpeg(tmp_path: Path) -> None:
    _set(tmp_path, size=(48, 64))  # wide image stored transposed (a viewer applied EXIF)
    code, out = _run("check-set", str(tmp_path))
    assert code == 2 and "is 48x64" in out and "64x48" in out and "EXIF orientation" in out


def test_check_set_without_decode_reads_headers(tmp_path: Path) -> None:
    root = _set(tmp_path, wide="w_text.png")
    (root / "w_text.png").write_text("not an image\n")
    code, out = _run("check-set", str(root))
    assert code == 2 and "w_text.png" in out and "not an image file" in out
    (root / "w_text.png").unlink()
    write_image(root / "w_text.png", np.zeros((30, 40), np.uint8))  # wrongly sized
    code, out = _run("check-set", str(root))
    assert code == 2 and "is 40x30" in out and "64x48" in out


# --- manifest -----------------------------------------------------------------------------------
def _manifest(**entry: object) -> str:
    base: dict[str, object] = {"id": "c1", "wide": "w.png", "tele": "t.png", "kind": "face",
                               "orientation": "landscape"}
    base.update(entry)
    return json.dumps({"schema_version": 1, "captures": [base]})


def test_manifest_path_may_not_leave_the_set() -> None:
    with pytest.raises(InputError, match="capture 'c1' field 'wide': must stay inside"):
        parse_manifest(_manifest(wide="../../other/images/x.png"))
    assert parse_manifest(_manifest(wide="sub/../w.png")).captures[0].wide == "sub/../w.png"


def test_orientation_is_a_bucket_case_normalised() -> None:
    assert ORIENTATION_BUCKETS == BUCKETS  # one list: the manifest accepts what fixes produce
    assert parse_manifest(_manifest(orientation="Landscape")).captures[0].orientation == "landscape"
    assert parse_manifest(_manifest(orientation="PORTRAIT_flipped")).captures[0].orientation == (
        "portrait-flipped"
    )
    with pytest.raises(InputError, match="capture 'c1' field 'orientation': unknown orientation"):
        parse_manifest(_manifest(orientation="sideways"))


def test_focus_mode_unknown_is_gated_with_a_reason() -> None:
    entry = parse_manifest(_manifest(time_s=300.0)).captures[0]
    assert entry.focus_mode == "unknown"
    gate = fixed_focus_gate(entry)
    assert not gate.passed and "focus mode unknown" in gate.reason and "manual" in gate.reason
    manual = entry.model_copy(update={"focus_mode": "manual"})
    assert fixed_focus_gate(manual).passed


def test_time_s_optional_and_the_heating_gate_says_which_check() -> None:
    entry = parse_manifest(_manifest()).captures[0]
    assert entry.time_s is None
    gate = heated_gate(entry, warmup_s=180.0)
    assert not gate.passed and "drift-rate check" in gate.reason and "time_s" in gate.reason
    rate_gate = WarmupGate(max_drift_rate_px_per_s=0.002)
    slow = rate_gate.check(entry, drift_rate_px_per_s=0.0005)
    fast = rate_gate.check(entry, drift_rate_px_per_s=0.01)
    assert slow.passed and "drift-rate check: no time_s" in slow.reason
    assert not fast.passed and "drift-rate check: no time_s" in fast.reason
    warm = heated_gate(entry.model_copy(update={"time_s": 200.0}), warmup_s=180.0)
    timed = WarmupGate(min_time_s=180.0).check({"time_s": 200.0})
    assert warm.passed and "warm-up time check" in timed.reason


def test_a_folder_as_image_and_an_infinite_t_are_named() -> None:
    # Issue #19: a folder was "not found"; t = inf was reported under the field T_tele_wide.R.
    with pytest.raises(InputError, match="is a folder, not an image file"):
        read_gray(Path(__file__).parent)
    d = calibration_to_dict(_cal())
    d["T_tele_wide"]["t"] = [float("inf"), 0.0, 0.0]
    with pytest.raises(InputError, match=r"field 'T_tele_wide\.t': must be 3 finite numbers"):
        calibration_from_dict(d)
