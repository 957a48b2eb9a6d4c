"""The module spec: presets, user JSON, typed errors for bad input (docs/architecture.md)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import phonestereo.cli.simulate  # noqa: F401  (registers `simulate` and `module`)
from phonestereo.cli.app import app
from phonestereo.errors import InputError, PhysicsError
from phonestereo.sim.module import (
    EFFECT_NAMES,
    ModuleSpec,
    list_presets,
    load_module,
    parse_module,
)


def _preset_dict(name: str = "folded-x3") -> dict:
    return json.loads(load_module(name).to_json())


def test_presets_are_listed_and_load() -> None:
    assert list_presets() == ("folded-x3", "nonfolded-x2", "periscope-x5")
    folded, nonfolded = load_module("folded-x3"), load_module("nonfolded-x2")
    # docs/architecture.md: f ≈ 1500 px wide, 4500 px tele (×3); ×2 tele of 8.4 mm
    # for the non-folded.
    assert folded.wide.focal_px_infinity == pytest.approx(1500.0)
    assert folded.tele.focal_px_infinity == pytest.approx(4500.0)
    assert nonfolded.tele.focal_px_infinity / nonfolded.wide.focal_px_infinity == pytest.approx(2)
    # Folded baseline 12 mm along device y with t_z ≈ 1.5 mm; non-folded ~10 mm along x.
    assert folded.extrinsics.tele_center_mm[1] == 12.0
    assert folded.extrinsics.tele_center_mm[2] == 1.5
    assert nonfolded.extrinsics.tele_center_mm[0] == 10.0
    assert folded.wide.lens.model == "radial-odd"


def test_json_round_trip_through_a_user_file(tmp_path: Path) -> None:
    spec = load_module("folded-x3")
    path = tmp_path / "mine.json"
    path.write_text(spec.to_json())
    assert load_module(path) == spec
    assert load_module(str(path)).to_json() == spec.to_json()


def test_effect_switches() -> None:
    spec = load_module("folded-x3")
    assert all(getattr(spec.effects, n) for n in EFFECT_NAMES)
    off = spec.with_effects(heating=False)
    assert not off.effects.heating and off.effects.sag
    assert not any(getattr(spec.all_effects_off().effects, n) for n in EFFECT_NAMES)
    with pytest.raises(InputError, match="unknown effect"):
        spec.with_effects(warp_drive=False)


def test_unknown_preset_lists_the_presets() -> None:
    with pytest.raises(InputError, match=r"folded-x3.*nonfolded-x2"):
        load_module("folded-x9")


def test_malformed_json_names_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "bad.json"
    path.write_text('{"name": "x",\n "wide": }')
    with pytest.raises(InputError, match=r"not valid JSON.*line 2, column"):
        load_module(path)


@pytest.mark.parametrize(
    ("edit", "error", "pattern"),
    [
        (lambda d: d["wide"].update(focal_length_mm=-4.2), PhysicsError, "wide.*focal_length_mm"),
        (lambda d: d["tele"].update(pixel_pitch_um=0), PhysicsError, "pixel_pitch_um"),
        (lambda d: d["extrinsics"].update(tele_center_mm=[0, 0, 0]), PhysicsError, "zero baseline"),
        (lambda d: d["wide"].update(f_number=-2), PhysicsError, "f_number"),
        (lambda d: d.update(colour="blue"), InputError, "colour.*Extra inputs"),
        (lambda d: d["wide"]["lens"].update(coefficients=[0.1]), InputError, "radial-odd"),
        (lambda d: d["wide"].update(size="big"), InputError, "wide.size"),
        (lambda d: d["effects"].update(heating="maybe"), InputError, "effects.heating"),
    ],
)
def test_bad_specs_raise_typed_errors_naming_the_field(edit, error, pattern) -> None:
    data = _preset_dict()
    edit(data)
    with pytest.raises(error, match=pattern):
        parse_module(data, "test")


def test_physics_errors_are_input_errors_too() -> None:
    data = _preset_dict()
    data["wide"]["focal_length_mm"] = -1.0
    with pytest.raises(InputError):  # PhysicsError subclasses InputError (errors.py)
        parse_module(data)
    with pytest.raises(InputError, match="JSON object"):
        parse_module([1, 2])


def test_module_cli_list_and_show() -> None:
    runner = CliRunner()
    listed = runner.invoke(app, ["module", "list", "--json"])
    assert listed.exit_code == 0, listed.output
    assert [m["name"] for m in json.loads(listed.output)] == list(list_presets())
    shown = runner.invoke(app, ["module", "show", "folded-x3", "--json"])
    assert shown.exit_code == 0, shown.output
    assert ModuleSpec.model_validate(json.loads(shown.output)) == load_module("folded-x3")
    table = runner.invoke(app, ["module", "show", "nonfolded-x2"])
    assert table.exit_code == 0 and "8.4" in table.output
    bad = runner.invoke(app, ["module", "show", "nope"])
    assert bad.exit_code == 2 and "folded-x3" in bad.output
