"""calibration.json: exact round trip, deterministic bytes, named fields on bad input."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from phonestereo.errors import InputError, PhysicsError, ShapeError
from phonestereo.geometry import Camera, Rig, Transform, make_lens
from phonestereo.io import (
    Calibration,
    CalibrationConditions,
    calibration_to_dict,
    load_calibration,
    save_calibration,
)


def folded_x3(lens_tele: str = "radial-odd") -> Calibration:
    """A folded-x3-like calibration, with awkward floats to test exact round trips."""
    wide = Camera(
        (2000, 1500),
        1501.234567891234,
        1500.987654321,
        1001.1 / 3,
        749.5 + 1e-7,
        make_lens("opencv5", [-0.071, 0.0213, 3.1e-4, -2.2e-4, -0.0031]),
    )
    tele_coeffs = (
        [0.011, -0.052, 0.031, 0.0, 1e-4, -2e-4]
        if lens_tele == "radial-odd"
        else [0.02, -0.1, 1e-4, 2e-4, 0.05, 0.01, -0.02, 0.003]
    )
    tele = Camera((2000, 1500), 4500.5, 4499.75, 1003.2, 747.9, make_lens(lens_tele, tele_coeffs))
    T = Transform.from_rotvec([0.003, -0.004, 0.0021], [0.0002, -0.012, 0.0015])
    rng = np.random.default_rng(7)
    a = rng.normal(size=(4, 4))
    cov = a @ a.T * 1e-6
    return Calibration(
        Rig(wide, tele, T),
        CalibrationConditions(focus_distance_m=0.6, temperature_c=24.5, orientation="landscape"),
        cov,
        ("wide.fx", "wide.cx", "tele.fx", "tele.cx"),
        0.31,
    )


def _same(a: Calibration, b: Calibration) -> None:
    assert a.rig.wide == b.rig.wide and a.rig.tele == b.rig.tele
    assert np.array_equal(a.rig.T_tele_wide.R, b.rig.T_tele_wide.R)
    assert np.array_equal(a.rig.T_tele_wide.t, b.rig.T_tele_wide.t)
    assert a.conditions == b.conditions and a.rms_px == b.rms_px
    assert a.parameter_names == b.parameter_names
    assert (a.covariance is None and b.covariance is None) or np.array_equal(
        a.covariance, b.covariance
    )


def test_json_round_trip_is_bit_exact_and_deterministic(tmp_path: Path) -> None:
    cal = folded_x3()
    p1 = save_calibration(tmp_path / "a" / "calibration.json", cal)
    back = load_calibration(p1)
    _same(cal, back)  # floats written by repr: bit-exact
    p2 = save_calibration(tmp_path / "b.json", back)
    assert p1.read_bytes() == p2.read_bytes()
    assert cal.std("tele.fx") == pytest.approx(np.sqrt(cal.covariance[2, 2]))  # type: ignore[index]
    # Minimal calibration: no covariance, default conditions.
    bare = Calibration(cal.rig)
    _same(bare, load_calibration(save_calibration(tmp_path / "c.json", bare)))


def _write(tmp_path: Path, data: dict[str, Any]) -> Path:
    p = tmp_path / "calibration.json"
    p.write_text(json.dumps(data))
    return p


@pytest.mark.parametrize(
    ("path", "value", "error", "expected"),
    [
        (("wide", "K", 0, 0), -1500.0, PhysicsError, "field 'wide.K': camera fx must be"),
        (("tele", "K", 1, 1), 0.0, PhysicsError, "field 'tele.K': camera fy must be"),
        (("T_tele_wide", "t"), [0.0, 0.0, 0.0], PhysicsError, "field 'T_tele_wide.t': rig"),
        (("T_tele_wide", "R", 0, 0), -1.0, InputError, "field 'T_tele_wide.R': R must be a rot"),
        (("T_tele_wide", "R"), [[1, 0], [0, 1]], ShapeError, "field 'T_tele_wide.R': must be"),
        (("T_tele_wide", "t"), [0.01, 0.0], ShapeError, "field 'T_tele_wide.t': must be 3"),
        (("wide", "lens", "model"), "fisheye", InputError, "field 'wide.lens': unknown lens"),
        (("wide", "lens", "coefficients"), [0.1], InputError, "field 'wide.lens': lens 'opencv5'"),
        (("wide", "size"), [2000.5, 1500], InputError, "field 'wide.size': must be [width"),
        (("wide", "K", 2, 0), 0.5, InputError, "field 'wide.K': K must be upper triangular"),
        (("covariance",), [[1.0, 0.0]], ShapeError, "field 'covariance': covariance must have"),
        (("conditions", "focus_distance_m"), -0.6, InputError, "'conditions.focus_distance_m'"),
        (("conditions", "temperature_c"), "hot", InputError, "'conditions.temperature_c'"),
        (("rms_px",), -0.1, InputError, "field 'rms_px': rms_px must be"),
        (("schema_version",), 2, InputError, "field 'schema_version': this phonestereo reads"),
        (("wide", "focal"), 1.0, InputError, "field 'wide.focal': unknown field"),
        (("T_tele_wide", "q"), 1.0, InputError, "field 'T_tele_wide.q': unknown field"),
    ],
)
def test_bad_fields_are_named_with_geometry_error_types(
    tmp_path: Path, path: tuple[Any, ...], value: Any, error: type, expected: str
) -> None:
    data = copy.deepcopy(calibration_to_dict(folded_x3()))
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(error) as info:
        load_calibration(_write(tmp_path, data))
    assert str(info.value).startswith("calibration.json: ")
    assert expected in str(info.value)


def test_missing_and_malformed_files(tmp_path: Path) -> None:
    data = calibration_to_dict(folded_x3())
    del data["tele"]
    with pytest.raises(InputError, match="field 'tele': required field is missing"):
        load_calibration(_write(tmp_path, data))
    with pytest.raises(InputError, match="not found"):
        load_calibration(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{\n  "wide": [1, 2\n}')
    with pytest.raises(InputError, match=r"bad.json: not valid JSON at line 3 column 1"):
        load_calibration(bad)


def test_dataclass_checks() -> None:
    rig = folded_x3().rig
    with pytest.raises(ShapeError, match="shape \\(P, P\\) = \\(2, 2\\)"):
        Calibration(rig, covariance=np.eye(3), parameter_names=("a", "b"))
    with pytest.raises(InputError, match="symmetric"):
        Calibration(rig, covariance=np.array([[1.0, 0.5], [0.0, 1.0]]), parameter_names=("a", "b"))
    with pytest.raises(InputError, match="unique"):
        Calibration(rig, covariance=np.eye(2), parameter_names=("a", "a"))
    cal = Calibration(rig, covariance=np.eye(2), parameter_names=("a", "b"))
    with pytest.raises(ValueError, match="read-only"):
        cal.covariance[0, 0] = 2.0  # type: ignore[index]
