"""Bad inputs found by the CLI sweep of issue #19: each gives exit 2, a message naming the
problem and the CLI flag or file that fixes it, and leaves the user's files as they were."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from _support.cli import run as _run
from _support.cli import tree as _tree
from phonestereo.errors import InputError
from phonestereo.io import write_image


def _simulate(out: Path, scenario: str, *extra: str) -> tuple[int, str]:
    return _run("simulate", scenario, "--quick", "--no-images", "--out", str(out), *extra)


def test_simulate_onto_a_capture_set_refuses_without_force(tmp_path: Path) -> None:
    # Was: exit 0, manifest and calibration overwritten, the old images left behind.
    out = tmp_path / "set"
    assert _simulate(out, "verification")[0] == 0
    (out / "images").mkdir(exist_ok=True)
    (out / "images" / "V00_0_wide.png").write_bytes(b"an image the user keeps")
    before = _tree(out)
    code, msg = _simulate(out, "heating", "--seed", "2")
    assert code == 2, msg
    assert "already holds a capture set" in msg and "--force" in msg and "--out" in msg
    assert _tree(out) == before  # nothing modified


def test_simulate_force_replaces_the_set_cleanly(tmp_path: Path) -> None:
    out = tmp_path / "set"
    code, msg = _run("simulate", "verification", "--quick", "--out", str(out))
    assert code == 0, msg
    old_images = {p.name for p in (out / "images").iterdir()}
    (out / "notes.txt").write_text("mine")  # not the set's: kept
    code, msg = _simulate(out, "heating", "--seed", "2", "--force")
    assert code == 0, msg
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["captures"][0]["id"].startswith("h")  # the heating set now
    # --no-images: the new set has no images, and none of the old set's is left behind
    assert old_images and not any((out / "images").iterdir())
    assert (out / "notes.txt").read_text() == "mine"


def test_simulate_into_a_folder_of_other_files_is_refused_even_with_force(tmp_path: Path) -> None:
    (tmp_path / "thesis.tex").write_text("mine")
    code, msg = _simulate(tmp_path, "verification", "--force")
    assert code == 2, msg
    assert "holds no capture set" in msg and "new or empty --out" in msg
    assert _tree(tmp_path) == {"thesis.tex": b"mine"}


def test_infinite_t_is_reported_under_t(tmp_path: Path) -> None:
    out = tmp_path / "set"
    assert _simulate(out, "verification")[0] == 0
    cal = json.loads((out / "calibration.json").read_text())
    cal["T_tele_wide"]["t"][0] = float("inf")
    path = tmp_path / "inf.json"
    path.write_text(json.dumps(cal))  # JSON 'Infinity', as Python writes it
    img = write_image(tmp_path / "w.png", np.zeros((8, 8), np.uint8))
    code, msg = _run(
        "rectify", str(img), str(img), "--calibration", str(path), "--mode", "canonical",
        "--out", str(tmp_path / "r"),
    )
    assert code == 2, msg
    # Was: "field 'T_tele_wide.R': t must be finite".
    assert "field 'T_tele_wide.t'" in msg and "finite" in msg and "T_tele_wide.R" not in msg
    assert not (tmp_path / "r").exists()


def test_a_folder_given_as_an_image_is_named_a_folder(tmp_path: Path) -> None:
    folder = tmp_path / "captures"
    folder.mkdir()
    for args in (["detect-chart", str(folder)], ["faces", str(folder)]):
        code, msg = _run(*args)
        assert code == 2, (args, msg)
        # Was: "image file not found" for a folder that exists.
        assert "is a folder, not an image file" in msg and "not found" not in msg, msg


def test_detect_chart_refuses_a_nan_rotation_hint(tmp_path: Path) -> None:
    img = write_image(tmp_path / "w.png", np.zeros((8, 8), np.uint8))
    for value in ("nan", "inf"):
        code, msg = _run("detect-chart", str(img), "--rotation-hint", value, "--json")
        assert code == 2, msg  # was exit 1, "no verification chart", the NaN used as a hint
        assert "--rotation-hint" in msg and "finite angle in degrees" in msg


def test_force_leaves_an_earlier_phone_dump_alone_and_says_so(tmp_path: Path) -> None:
    from phonestereo.cli.outputs import prepare_capture_set_folder

    out = tmp_path / "set"
    assert _simulate(out, "verification")[0] == 0
    (out / "android").mkdir()
    (out / "android" / "capture.json").write_text("{}")  # as `simulate --export android` leaves
    before = _tree(out)
    with pytest.raises(InputError, match=r"also holds android .*remove those folders"):
        prepare_capture_set_folder(out, force=True)
    assert _tree(out) == before  # refused before anything was removed
