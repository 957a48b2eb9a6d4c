"""Random modules (issue #18 item 1) and the periscope-x5 preset: drawn within the documented
ranges, physically consistent, reproducible."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.sim.isp_spec import IspSpec
from phonestereo.sim.module import load_module, parse_module
from phonestereo.sim.random_module import load_ranges, random_module

SEEDS = range(1000, 1020)  # the acceptance seeds of issue #18


def test_same_seed_same_module_and_seeds_differ() -> None:
    a, b = random_module(1003), random_module(1003)
    assert a.to_json() == b.to_json()  # byte for byte
    assert random_module(1004).to_json() != a.to_json()


@pytest.mark.parametrize("seed", SEEDS)
def test_random_module_is_within_the_ranges_and_parses(seed: int) -> None:
    r = load_ranges()
    spec = random_module(seed)
    # Round trip through the JSON schema: what `module random --out` writes loads again.
    assert parse_module(json.loads(spec.to_json())) == spec
    w, t = spec.wide, spec.tele
    assert w.size == t.size and w.size[1] * 4 == w.size[0] * 3
    assert 2000 <= w.size[0] <= 4000
    ratio = t.focal_px_infinity / w.focal_px_infinity
    assert 2.0 <= ratio <= 6.0  # the tele's field is inside the wide's (same output size)
    hfov = np.degrees(2 * np.arctan(w.size[0] / 2 / w.focal_px_infinity))
    assert 64.0 - 0.1 <= hfov <= 80.0 + 0.1  # rounding of f_mm to 0.1 µm
    for cam, diag in ((w, r.wide_sensor_diagonal_mm), (t, r.tele_sensor_diagonal_mm)):
        assert 0.8 <= cam.pixel_pitch_um <= 2.8
        d_mm = cam.pixel_pitch_um * 1e-3 * float(np.hypot(*cam.size))
        assert diag[0] - 1e-3 <= d_mm <= diag[1] + 1e-3
        assert float(np.hypot(*cam.heating_drift_px)) <= 7.0 + 1e-3
    assert t.focal_length_mm / t.f_number <= 5.0 + 0.01  # aperture ≤ 5 mm (prism height)
    tc = spec.extrinsics.tele_center_mm
    assert 8.0 - 1e-3 <= float(np.hypot(tc[0], tc[1])) <= 25.0 + 1e-3
    assert 0.0 <= tc[2] <= 6.0
    assert max(abs(v) for v in spec.extrinsics.rotation_deg) <= 0.6
    assert 0.01 <= spec.autofocus.error_dioptre <= 0.08
    assert 0.0 <= spec.autofocus.failure_rate <= 0.12
    assert 0 <= t.sag_px_per_g <= 1.5
    base = load_module("folded-x3").calibration.noise.rotation_deg
    assert spec.calibration.noise.rotation_deg <= 3 * base + 1e-9


def test_the_seeds_span_the_ranges() -> None:
    # 20 seeds reach both ends of the zoom range and both temperature cases (not all x3).
    specs = [random_module(s) for s in SEEDS]
    ratios = [s.tele.focal_px_infinity / s.wide.focal_px_infinity for s in specs]
    assert min(ratios) < 2.5 and max(ratios) > 5.0
    assert {s.reports.temperature for s in specs} == {True, False}


def test_ranges_file_overrides_and_errors(tmp_path) -> None:
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"focal_ratio": [5.0, 5.0], "tz_mm": [4.0, 4.0]}))
    spec = random_module(7, load_ranges(path))
    assert spec.tele.focal_px_infinity / spec.wide.focal_px_infinity == pytest.approx(5.0, 1e-3)
    assert spec.extrinsics.tele_center_mm[2] == 4.0
    path.write_text(json.dumps({"focal_ratio": [6.0, 2.0]}))
    with pytest.raises(InputError, match="focal_ratio"):
        load_ranges(path)
    path.write_text(json.dumps({"warp": [1, 2]}))
    with pytest.raises(InputError, match="warp"):
        load_ranges(path)
    impossible = tmp_path / "x.json"
    impossible.write_text(json.dumps({"pixel_pitch_um": [0.8, 0.8], "width_px": [2000, 2000]}))
    with pytest.raises(InputError, match="no physical module"):
        random_module(1, load_ranges(impossible))
    with pytest.raises(InputError, match="seed"):
        random_module(-1)


def test_periscope_x5_preset_is_the_held_out_module_described_in_issue_18() -> None:
    spec = load_module("periscope-x5")
    ratio = spec.tele.focal_px_infinity / spec.wide.focal_px_infinity
    assert ratio == pytest.approx(5.0)
    tc = np.array(spec.extrinsics.tele_center_mm)
    assert float(np.hypot(tc[0], tc[1])) == pytest.approx(17.0, abs=0.1)  # diagonal
    assert abs(tc[0]) == pytest.approx(abs(tc[1]))
    assert tc[2] == pytest.approx(4.0)
    folded = load_module("folded-x3")
    assert spec.tele.pixel_pitch_um < folded.tele.pixel_pitch_um  # smaller pixels
    assert spec.wide.pixel_pitch_um < folded.wide.pixel_pitch_um
    # A phone ISP per camera; the periscope's small-pixel tele is denoised harder than any
    # preset tele and sharpened less than its wide (docs/module.md, typical phone values).
    assert spec.isp("wide") is not None and spec.isp("tele") is not None
    assert spec.tele.isp.denoise_strength > folded.tele.isp.denoise_strength
    assert spec.tele.isp.denoise_strength > spec.wide.isp.denoise_strength
    assert spec.tele.isp.sharpen_amount < spec.wide.isp.sharpen_amount


def _within(value: float, pair: tuple[float, float]) -> bool:
    # The drawn values are rounded to 3 decimals: 1e-3 of slack.
    return pair[0] - 1e-3 <= value <= pair[1] + 1e-3


@pytest.mark.parametrize("seed", SEEDS)
def test_random_isp_blocks_validate_and_respect_their_ranges(seed: int) -> None:
    r = load_ranges()
    spec = random_module(seed)
    for cam, isp_r in ((spec.wide, r.wide_isp), (spec.tele, r.tele_isp)):
        isp = cam.isp
        assert isp is not None
        IspSpec.model_validate(isp.model_dump())  # a valid block (the JSON schema's checks)
        assert isp.cfa_pattern in isp_r.cfa_patterns
        assert isp.demosaic in isp_r.demosaic_methods
        assert isp.raw_bit_depth in isp_r.raw_bit_depths
        assert isp.raw_black_level_dn == 64 * 2 ** (isp.raw_bit_depth - 10)
        assert _within(isp.channel_sensitivity[0], isp_r.red_sensitivity)
        assert _within(isp.channel_sensitivity[2], isp_r.blue_sensitivity)
        for name in ("ccm_strength", "tone_gamma", "denoise_strength", "denoise_radius_px",
                     "sharpen_amount", "sharpen_radius_px", "chroma_blur_px",
                     "chroma_saturation", "jpeg_quality"):
            assert _within(getattr(isp, name), getattr(isp_r, name)), name
    # Drawn independently: the two cameras never share one tuning.
    assert spec.wide.isp != spec.tele.isp


def test_the_isp_draw_leaves_the_rest_of_a_seed_as_it_was(tmp_path) -> None:
    # The ISP has its own random stream: switching it off changes nothing else, so the
    # modules measured before the ISP was drawn (random-1006, random-1010) keep their optics.
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"isp": False}))
    raw = random_module(1006, load_ranges(path))
    drawn = random_module(1006)
    assert raw.wide.isp is None and raw.tele.isp is None
    assert raw.model_copy(update={"description": ""}) == drawn.model_copy(update={
        "description": "", "wide": drawn.wide.model_copy(update={"isp": None}),
        "tele": drawn.tele.model_copy(update={"isp": None})})
    assert (drawn.tele.focal_length_mm, drawn.wide.size) == (5.3854, (2080, 1560))  # as on main


def test_isp_ranges_are_overridable_key_by_key(tmp_path) -> None:
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"tele_isp": {"jpeg_quality": [90, 90],
                                             "demosaic_methods": ["vng"]}}))
    r = load_ranges(path)
    assert r.tele_isp.denoise_strength == load_ranges().tele_isp.denoise_strength  # merged
    for seed in (1, 2, 3):
        tele = random_module(seed, r).tele.isp
        assert tele is not None and tele.jpeg_quality == 90 and tele.demosaic == "vng"
    path.write_text(json.dumps({"wide_isp": {"sharpen_amount": [2.0, 1.0]}}))
    with pytest.raises(InputError, match="sharpen_amount"):
        load_ranges(path)
    path.write_text(json.dumps({"wide_isp": {"cfa_patterns": ["RGBW"]}}))
    with pytest.raises(InputError, match="cfa_patterns"):
        load_ranges(path)
