"""Capture-set manifest: validation messages name the capture and field (docs/capture-set.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.io import (
    CaptureEntry,
    Manifest,
    load_capture_set,
    parse_manifest,
    write_manifest,
)

BASE: dict[str, Any] = {
    "id": "v03",
    "wide": "v03_wide.png",
    "tele": "v03_tele.png",
    "time_s": 185.5,
    "gravity": [0.0, 1.0, 0.0],
    "kind": "verification",
}


def _doc(*captures: dict[str, Any], **top: Any) -> str:
    return json.dumps({**top, "captures": list(captures)}, indent=2)


def _make_set(tmp_path: Path, manifest: Manifest) -> Path:
    write_manifest(tmp_path, manifest)
    (tmp_path / "img").mkdir()
    for c in manifest.captures:
        (tmp_path / c.wide).write_bytes(b"x")
        (tmp_path / c.tele).write_bytes(b"x")
    (tmp_path / manifest.calibration).write_text("{}")
    return tmp_path


def _manifest() -> Manifest:
    caps = [
        CaptureEntry(
            id=f"f{i:02d}",
            wide=f"img/f{i:02d}_wide.png",
            tele=f"img/f{i:02d}_tele.png",
            time_s=180.0 + i,
            orientation="landscape",
            kind="face",
            focus_group="stack1",
            focus_attempt=i,
            temperature_c=41.5,
            roi=(900, 600, 200, 150),
        )
        for i in range(3)
    ]
    return Manifest(description="test set", captures=caps)


def test_valid_entry_parses_with_defaults() -> None:
    m = parse_manifest(_doc(BASE))
    c = m.captures[0]
    assert (c.id, c.gravity, c.focus_mode, c.orientation) == (
        "v03",
        (0.0, 1.0, 0.0),
        "unknown",  # issue #17: no silent "manual"; the fixed-focus gate says it is unknown
        None,
    )
    assert m.schema_version == 1 and m.calibration == "calibration.json"


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ({"gravity": [0, 2, 0]}, "capture 'v03' field 'gravity': must be a unit vector"),
        ({"gravity": [0, 1]}, "capture 'v03' field 'gravity': too few values"),
        ({"exposure_ms": 3}, "capture 'v03' field 'exposure_ms': unknown field"),
        ({"kind": "selfie"}, "capture 'v03' field 'kind':"),
        ({"time_s": -1.0}, "capture 'v03' field 'time_s':"),
        ({"time_s": "1.0"}, "capture 'v03' field 'time_s':"),  # strict: no str → float
        ({"time_s": float("nan")}, "capture 'v03' field 'time_s':"),
        ({"roi": [10, 10, 0, 5]}, "capture 'v03' field 'roi': must be [x, y, w, h]"),
        ({"roi": [10.5, 10, 4, 5]}, "capture 'v03' field 'roi[0]':"),
        ({"focus_attempt": -1}, "capture 'v03' field 'focus_attempt':"),
        ({"focus_mode": "continuous"}, "capture 'v03' field 'focus_mode':"),
        ({"wide": "/abs/w.png"}, "capture 'v03' field 'wide': must be a path relative"),
        ({"tele": ""}, "capture 'v03' field 'tele':"),
        ({"gravity": None}, "capture 'v03': needs 'gravity'"),
        ({"id": ""}, "capture #0 (no valid id) field 'id': must be a non-empty string"),
    ],
)
def test_invalid_entry_names_capture_and_field(change: dict[str, Any], expected: str) -> None:
    entry = {k: v for k, v in {**BASE, **change}.items() if v is not None or k != "gravity"}
    with pytest.raises(InputError) as info:
        parse_manifest(_doc(entry))
    assert str(info.value).startswith("manifest.json: ")
    assert expected in str(info.value)


def test_missing_field_and_many_errors() -> None:
    entry = {k: v for k, v in BASE.items() if k != "tele"}
    with pytest.raises(InputError, match="capture 'v03' field 'tele': required field is missing"):
        parse_manifest(_doc(entry))
    # Every bad entry is reported, each with its own capture id.
    with pytest.raises(InputError) as info:
        parse_manifest(
            _doc(
                {**BASE, "id": "a", "gravity": [0, 0, 3]},
                {**BASE, "id": "b"},
                {**BASE, "id": "c", "kind": "x"},
            )
        )
    msg = str(info.value)
    assert "capture 'a' field 'gravity'" in msg and "capture 'c' field 'kind'" in msg
    assert "capture 'b'" not in msg


def test_document_level_errors() -> None:
    with pytest.raises(InputError, match="repeated: \\['v03'\\]"):
        parse_manifest(_doc(BASE, BASE))
    with pytest.raises(InputError, match="field 'schema_version': this phonestereo reads"):
        parse_manifest(_doc(BASE, schema_version=2))
    with pytest.raises(InputError, match="field 'captures': required field is missing"):
        parse_manifest("{}")
    with pytest.raises(InputError, match="must be a JSON object"):
        parse_manifest("[]")
    with pytest.raises(InputError, match="field 'extra': unknown field"):
        parse_manifest(_doc(BASE, extra=1))
    # Bad JSON: line and column of the error (after the trailing comma on line 2).
    with pytest.raises(InputError, match="not valid JSON at line 2 column 14"):
        parse_manifest('{"captures": [\n  {"id": "a",}\n]}')


def test_write_is_deterministic_and_round_trips(tmp_path: Path) -> None:
    m = _manifest()
    a = write_manifest(tmp_path / "a", m).read_bytes()
    b = write_manifest(tmp_path / "b", Manifest.model_validate(m.model_dump())).read_bytes()
    assert a == b
    assert parse_manifest(a.decode()) == m
    assert b"null" not in a  # None fields are left out, not written as null


def test_capture_set_accessors(tmp_path: Path) -> None:
    root = _make_set(tmp_path, _manifest())
    cs = load_capture_set(root)
    assert [c.id for c in cs.captures()] == ["f00", "f01", "f02"]
    assert cs.get("f01").focus_attempt == 1
    wide, tele = cs.image_paths("f02")
    assert wide == root / "img/f02_wide.png" and tele == root / "img/f02_tele.png"
    assert cs.calibration_path() == root / "calibration.json"
    with pytest.raises(InputError, match=r"no capture 'zz'.*known ids: 'f00', 'f01', 'f02'"):
        cs.get("zz")
    # The manifest file itself is accepted in place of the folder.
    assert load_capture_set(root / "manifest.json").root == root


def test_missing_files_are_named(tmp_path: Path) -> None:
    root = _make_set(tmp_path, _manifest())
    (root / "img/f01_tele.png").unlink()
    with pytest.raises(InputError) as info:
        load_capture_set(root)
    msg = str(info.value)
    assert "capture 'f01' field 'tele': image file not found" in msg
    assert "f01_tele.png" in msg and "fix the path" in msg
    assert load_capture_set(root, check_images=False).get("f01").id == "f01"
    (root / "img/f01_tele.png").write_bytes(b"x")
    (root / "calibration.json").unlink()
    with pytest.raises(InputError, match="field 'calibration': calibration file not found"):
        load_capture_set(root)
    with pytest.raises(InputError, match="does not exist"):
        load_capture_set(tmp_path / "nowhere")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match=r"no manifest.json"):
        load_capture_set(empty)


def test_python_construction_accepts_numpy_values() -> None:
    # The simulator builds entries from NumPy values; they validate like plain numbers.
    g = np.array([0.0, 0.6, 0.8])
    c = CaptureEntry(
        id="s1",
        wide="w.png",
        tele="t.png",
        time_s=np.float64(12.5),
        gravity=tuple(g),
        kind="scene",
        roi=tuple(np.array([1, 2, 3, 4])),
    )
    assert c.gravity == (0.0, 0.6, 0.8) and c.roi == (1, 2, 3, 4)
    with pytest.raises(ValueError, match="unit vector"):
        CaptureEntry(id="s1", wide="w", tele="t", time_s=0, gravity=(0, 0, 0.5), kind="scene")
