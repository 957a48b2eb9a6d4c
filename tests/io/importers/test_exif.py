"""EXIF importer: pairing by capture time, orientation tags, and refusal of what EXIF lacks."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest
from PIL import Image
from typer.testing import CliRunner

from phonestereo.cli import app
from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.io import Calibration, load_capture_set, save_calibration
from phonestereo.io.importers.exif import import_exif

T0 = dt.datetime(2026, 3, 1, 10, 0, 0)


def _jpeg(path: Path, size: tuple[int, int], when: dt.datetime | None, focal: float,
          orientation: int | None = 6, distance: float | None = None) -> None:
    exif = Image.Exif()
    if orientation is not None:
        exif[0x0112] = orientation
    ifd = exif.get_ifd(0x8769)
    if when is not None:
        ifd[0x9003] = when.strftime("%Y:%m:%d %H:%M:%S")
        ifd[0x9291] = f"{when.microsecond // 1000:03d}"
    ifd[0x920A] = focal
    if distance is not None:
        ifd[0x9206] = distance
    Image.new("RGB", size, (90, 90, 90)).save(path, exif=exif)


@pytest.fixture()
def shots(tmp_path: Path) -> Path:
    wide, tele = (
        Camera((64, 48), 50.0, 50.0, 31.5, 23.5),
        Camera((64, 48), 150.0, 150.0, 31.5, 23.5),
    )
    cal = Calibration(Rig(wide, tele, Transform.from_rotvec([0, 0, 0], [0, -0.012, 0])))
    save_calibration(tmp_path / "calibration.json", cal)
    for i in range(3):
        t = T0 + dt.timedelta(seconds=10 * i, milliseconds=250)
        _jpeg(tmp_path / f"wide_{i}.jpg", (64, 48), t, 4.2, distance=2.0)
        _jpeg(tmp_path / f"tele_{i}.jpg", (64, 48), t + dt.timedelta(milliseconds=30), 12.6)
    # A tele shot with no wide partner within the 1 s window:
    _jpeg(tmp_path / "tele_9.jpg", (64, 48), T0 + dt.timedelta(seconds=100), 12.6)
    return tmp_path


def _import(d: Path, **kw: object) -> object:
    args = {"kind": "scene", "focus_mode": "auto", "time_offset_s": 200.0, **kw}
    return import_exif(str(d / "wide_*.jpg"), str(d / "tele_*.jpg"), d / "calibration.json",
                       d / "set", **args)  # type: ignore[arg-type]


def test_pairs_by_capture_time_and_maps_exif_fields(shots: Path) -> None:
    result = _import(shots)
    caps = load_capture_set(shots / "set").captures()
    assert [c.time_s for c in caps] == [200.0, 210.0, 220.0]  # offset + time since first pair
    assert {c.orientation for c in caps} == {"portrait"}  # EXIF Orientation 6
    assert caps[0].focus_position == pytest.approx(0.5)  # 1 / SubjectDistance 2 m
    assert caps[0].focus_mode == "auto" and caps[0].kind == "scene"
    assert any("tele_9.jpg" in n and "left out" in n for n in result.notes)  # type: ignore[attr-defined]


def test_missing_capture_time_names_the_tag(shots: Path) -> None:
    _jpeg(shots / "wide_1.jpg", (64, 48), None, 4.2)
    with pytest.raises(InputError, match="DateTimeOriginal"):
        _import(shots)
    assert not (shots / "set").exists()


def test_missing_orientation_needs_the_flag(shots: Path) -> None:
    for i in range(3):
        _jpeg(shots / f"wide_{i}.jpg", (64, 48), T0 + dt.timedelta(seconds=10 * i), 4.2, None)
        _jpeg(shots / f"tele_{i}.jpg", (64, 48), T0 + dt.timedelta(seconds=10 * i), 12.6, None)
    with pytest.raises(InputError, match="--orientation"):
        _import(shots)
    _import(shots, orientation="face-up")
    assert {c.orientation for c in load_capture_set(shots / "set").captures()} == {"face-up"}


def test_swapped_globs_and_wrong_sizes_are_refused(shots: Path) -> None:
    with pytest.raises(InputError, match="swap the two globs"):
        import_exif(str(shots / "tele_*.jpg"), str(shots / "wide_*.jpg"),
                    shots / "calibration.json", shots / "set", kind="scene",
                    focus_mode="auto", time_offset_s=0.0)
    _jpeg(shots / "tele_2.jpg", (48, 64), T0 + dt.timedelta(seconds=20), 12.6)
    with pytest.raises(InputError, match=r"stored size 48×64.*calibration's tele size"):
        _import(shots)


def test_cli_asks_for_what_exif_lacks(shots: Path) -> None:
    base = ["import", "exif", str(shots / "wide_*.jpg"), str(shots / "tele_*.jpg"),
            "--calibration", str(shots / "calibration.json"), "--out", str(shots / "set"),
            "--kind", "scene", "--time-offset-s", "0"]
    r = CliRunner().invoke(app, base)
    assert r.exit_code == 2 and "--focus-mode" in r.output
    r = CliRunner().invoke(app, [*base, "--focus-mode", "auto", "--json"])
    assert r.exit_code == 0, r.output
    assert '"captures": 3' in r.output
