"""Bad inputs found by the second CLI sweep (the commands added or grown since issue #19's):
each gives exit 2, a message naming the problem and the CLI flag that fixes it, no traceback,
and leaves the user's files as they were. Outputs never overwrite a file without --force."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from _support.cli import run, stamp, tree
from phonestereo.io import write_image
from phonestereo.learning.store import FixStore

#: Not UTF-8: what a careless user passes when they pick the wrong file (a photo, a zip).
BINARY = bytes(range(128, 256)) * 2


@pytest.fixture(scope="module")
def sim_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small simulated verification set (JSON only): manifest, calibration, ground truth."""
    out = tmp_path_factory.mktemp("sim") / "set"
    code, msg = run("simulate", "verification", "--quick", "--no-images", "--out", str(out))
    assert code == 0, msg
    return out


def _refused(code: int, msg: str, *words: str) -> None:
    assert code == 2, msg
    assert "Traceback" not in msg
    for w in words:
        assert w in msg, (w, msg)


# --- outputs: an existing file is never overwritten without --force ---------------------------


def test_module_random_out_onto_an_existing_file_refuses_and_force_overwrites(
    tmp_path: Path,
) -> None:
    mine = tmp_path / "module.json"
    mine.write_text('{"mine": 1}')
    before = stamp(mine)
    # Was: exit 0, the file silently replaced (and no --force existed).
    _refused(*run("module", "random", "--seed", "1", "--out", str(mine)),
             "--out", "already exists", "--force")
    assert stamp(mine) == before
    code, msg = run("module", "random", "--seed", "1", "--out", str(mine), "--force")
    assert code == 0, msg
    assert json.loads(mine.read_text())["name"] == "random-1"


@pytest.mark.parametrize(
    ("where", "words"),
    [
        ("folder", ("is a folder", "file path")),  # was: IsADirectoryError traceback
        ("under-a-file", ("is a file", "choose another --out")),  # was: FileExistsError
        ("wrong-suffix", ("must end in .json",)),  # was: JSON written to module.png
    ],
)
def test_module_random_out_of_the_wrong_kind_is_refused(
    tmp_path: Path, where: str, words: tuple[str, ...]
) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    out = {"folder": tmp_path, "under-a-file": notes / "m.json",
           "wrong-suffix": tmp_path / "module.png"}[where]
    _refused(*run("module", "random", "--seed", "1", "--out", str(out)), "--out", *words)
    assert tree(tmp_path) == {"notes.txt": b"mine"}


def _existing_output_cases(sim: Path, tmp: Path) -> dict[str, tuple[list[str], Path, str]]:
    """Per command: its arguments writing onto a user's existing file, the file, the flag."""
    store = tmp / "fixes.sqlite"
    with FixStore(store):
        pass
    img = write_image(tmp / "photo.png", np.full((40, 60), 128, np.uint8))
    cal = str(sim / "calibration.json")
    f = {n: tmp / n for n in ("obs.csv", "chart.pdf", "cal.json", "overlay.png", "r.html")}
    return {
        "store export": (["store", "export", str(store), "--out", str(f["obs.csv"])],
                         f["obs.csv"], "--out"),
        "chart": (["chart", "verification", "--out", str(f["chart.pdf"])], f["chart.pdf"],
                  "--out"),
        "convert-calibration": (["convert-calibration", cal, str(f["cal.json"])], f["cal.json"],
                                "DST"),
        "calibrate": (["calibrate", "--board", "9x6", "--square-m", "0.025", "--wide",
                       str(tmp / "*.jpg"), "--out", str(f["cal.json"])], f["cal.json"], "--out"),
        "detect-chart": (["detect-chart", str(img), "--overlay", str(f["overlay.png"])],
                         f["overlay.png"], "--overlay"),
        "faces": (["faces", str(img), "--overlay", str(f["overlay.png"])], f["overlay.png"],
                  "--overlay"),
        "evaluate": (["evaluate", str(sim), "--report", str(f["r.html"])], f["r.html"],
                     "--report"),
    }


@pytest.mark.parametrize(
    "command",
    ["store export", "chart", "convert-calibration", "calibrate", "detect-chart", "faces",
     "evaluate"],
)
def test_a_file_output_onto_an_existing_file_is_refused_without_force(
    tmp_path: Path, sim_set: Path, command: str
) -> None:
    # Was: exit 0 (or 1) with the user's file overwritten (calibrate and evaluate after their
    # work; detect-chart even onto its own input image).
    args, mine, flag = _existing_output_cases(sim_set, tmp_path)[command]
    mine.write_bytes(b"the user's own file")
    before = stamp(mine)
    _refused(*run(*args), flag, "already exists", "pass --force to overwrite it")
    assert stamp(mine) == before


def test_convert_calibration_onto_its_own_source_needs_force(sim_set: Path) -> None:
    cal = sim_set / "calibration.json"
    before = stamp(cal)
    _refused(*run("convert-calibration", str(cal), str(cal)), "DST", "already exists", "--force")
    assert stamp(cal) == before


def test_an_output_in_a_read_only_folder_is_refused_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Was: an OSError traceback (chart, module random, store export, convert-calibration,
    # overlays, rectify, analyze, import) once the work was done. os.access stands in for a
    # read-only mount (root can write a chmod-ed folder).
    real = os.access
    locked = tmp_path / "locked"
    locked.mkdir()
    monkeypatch.setattr(
        "phonestereo.cli.outputs.os.access",
        lambda p, mode: False if Path(p) == locked else real(p, mode),
    )
    for args in (["chart", "verification", "--out", str(locked / "c.pdf")],
                 ["module", "random", "--seed", "1", "--out", str(locked / "m.json")]):
        _refused(*run(*args), "--out", "is not writable for you", "choose another --out",
                 "nothing was written")  # (Rich may wrap the long path: not compared)
    assert not any(locked.iterdir())


def test_demo_onto_an_earlier_capture_set_refuses_without_force(sim_set: Path) -> None:
    before = tree(sim_set)
    # Was: the whole bench rendered over the set (exit 0), the old files overwritten.
    _refused(*run("demo", "--out", str(sim_set)), "already holds a capture set", "--force")
    assert tree(sim_set) == before


# --- inputs: unreadable, non-physical, non-finite --------------------------------------------


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["config", "show", "--config", "{f}"], ("cannot read --config", "not UTF-8")),
        (["module", "show", "{f}"], ("cannot read module file",)),
        (["module", "random", "--seed", "1", "--ranges", "{f}"], ("cannot read --ranges",)),
        (["demo", "--module", "{f}", "--out", "{o}"], ("cannot read module file",)),
        (["study", "--module", "folded-x3", "--tolerances", "{f}", "--samples", "2", "--out",
          "{o}"], ("cannot read tolerances file", "--tolerances")),
    ],
)
def test_a_binary_file_given_as_json_is_an_error_not_a_traceback(
    tmp_path: Path, args: list[str], words: tuple[str, ...]
) -> None:
    f = tmp_path / "photo.json"
    f.write_bytes(BINARY)
    filled = [a.format(f=f, o=tmp_path / "out") for a in args]
    _refused(*run(*filled), *words)  # was: UnicodeDecodeError traceback, exit 1
    assert f.read_bytes() == BINARY and not (tmp_path / "out").exists()


def test_demo_with_an_unknown_module_is_an_error_not_a_traceback(tmp_path: Path) -> None:
    _refused(*run("demo", "--module", "nope", "--out", str(tmp_path / "d")),
             "unknown module 'nope'", "presets are")  # was: InputError traceback, exit 1
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize(
    ("ranges", "words"),
    [
        ({"baseline_mm": [0, 0]}, ("baseline_mm must be > 0", "stereo pair")),
        ({"baseline_mm": [-5, 5]}, ("baseline_mm must be > 0",)),
        ({"af_failure_rate": [0.5, 2]}, ("af_failure_rate must be within [0, 1]",)),
        ({"distortion_scale": [-2, -1]}, ("distortion_scale must be >= 0",)),
    ],
)
def test_module_random_refuses_non_physical_ranges(
    tmp_path: Path, ranges: dict[str, list[float]], words: tuple[str, ...]
) -> None:
    f = tmp_path / "ranges.json"
    f.write_text(json.dumps(ranges))
    # Was: exit 0 and a module drawn with a 0 mm baseline (no stereo pair), a failure rate of
    # 1.6, or distortion of the opposite sign.
    code, msg = run("module", "random", "--seed", "1", "--ranges", str(f), "--json")
    _refused(code, msg, "--ranges", *words)
    assert "(: Value error" not in msg  # pydantic's empty location is not shown


def test_config_refuses_an_infinite_knob(tmp_path: Path) -> None:
    f = tmp_path / "flow.json"
    f.write_text('{"warmup_s": Infinity}')  # as Python's json writes float("inf")
    # Was: exit 0, every capture gated as cold for ever.
    _refused(*run("config", "show", "--config", str(f)), "knob warmup_s is inf", "finite")


@pytest.mark.parametrize("command", ["stats", "vacuum", "export"])
def test_an_empty_file_is_not_made_into_a_store_by_a_store_command(
    tmp_path: Path, command: str
) -> None:
    empty = tmp_path / "fixes.sqlite"
    empty.touch()
    before = stamp(empty)
    extra = ["--out", str(tmp_path / "o.csv")] if command == "export" else []
    # Was: exit 0, a new store written into the user's file ("Never writes to a file that is
    # not a fix store").
    _refused(*run("store", command, str(empty), *extra), "is an empty file, not a fix store")
    assert stamp(empty) == before and not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--square-mm", "0"], ("--square-mm", "positive")),  # was: exit 0, a 25 mm chart
        (["--square-mm", "nan"], ("--square-mm", "positive")),  # was: named square_m
        (["--dpi", "-1", "--out-png"], ("--dpi", "positive")),  # was: named px_per_m
        (["--dpi", "1e7", "--out-png"], ("--dpi", "lower --dpi")),  # was: MemoryError
    ],
)
def test_chart_refuses_non_physical_sizes_naming_the_flag(
    tmp_path: Path, extra: list[str], words: tuple[str, ...]
) -> None:
    out = tmp_path / ("c.png" if "--out-png" in extra else "c.pdf")
    args = [a for a in extra if a != "--out-png"]
    code, msg = run("chart", "verification", "--out", str(out), *args)
    _refused(code, msg, *words)
    assert "square_m " not in msg and "px_per_m" not in msg and not out.exists()


def test_import_exif_refuses_a_nan_time_offset_and_gap(tmp_path: Path) -> None:
    common = ["import", "exif", "w*.jpg", "t*.jpg", "--calibration", str(tmp_path / "c.json"),
              "--kind", "scene", "--focus-mode", "auto", "--out", str(tmp_path / "set")]
    # Was: NaN accepted (the error that followed was about the calibration or EXIF).
    _refused(*run(*common, "--time-offset-s", "nan"), "--time-offset-s", "got nan")
    _refused(*run(*common, "--time-offset-s", "0", "--max-gap-s", "-1"),
             "--max-gap-s must be a positive number of seconds")


def test_a_folder_given_as_the_calibration_is_named_a_folder(tmp_path: Path) -> None:
    code, msg = run("convert-calibration", str(tmp_path), str(tmp_path / "c.json"))
    # Was: "not found" for a folder that exists.
    _refused(code, msg, "is a folder", "calibration.json")
    code, msg = run("convert-calibration", str(tmp_path / "nope.json"), str(tmp_path / "c.json"))
    # Was: "import an OpenCV YAML with import_opencv_yaml", a Python function.
    _refused(code, msg, "not found", "phonestereo convert-calibration")
    assert "import_opencv_yaml" not in msg
