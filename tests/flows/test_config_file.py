"""``--config FLOW.json`` (issue #19 item 3): the schema, validation, ``config show``, docs."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import phonestereo.cli  # noqa: F401  (registers every command)
from phonestereo.cli.app import app
from phonestereo.errors import InputError
from phonestereo.features.match_config import MatchConfig
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.config_file import (
    flow_config_from_dict,
    flow_config_json,
    knobs_markdown,
    load_flow_config,
)
from phonestereo.flows.config_knobs import KNOBS
from phonestereo.flows.roi_disparity import RoiConfig, measure_roi
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.rectification import Rectification

DOC = Path(__file__).parents[2] / "docs" / "flow-config.md"
runner = CliRunner()


def test_every_knob_is_documented() -> None:
    for section, cls in (("flow", FlowConfig), ("roi", RoiConfig), ("match", MatchConfig)):
        names = [f.name for f in dataclasses.fields(cls) if f.name not in ("roi", "match")]
        assert list(KNOBS[section]) == names, section  # no knob missing, none stale
        for name, (unit, meaning, why) in KNOBS[section].items():
            assert unit and len(meaning) > 10 and why, f"{section}.{name}"
    text = DOC.read_text()
    block = text[text.index("<!-- knobs:begin -->\n") + 21 : text.index("<!-- knobs:end -->")]
    assert block == knobs_markdown(), "docs/flow-config.md is stale: regenerate its tables"
    assert sum(len(v) for v in KNOBS.values()) >= 55  # the ~60 knobs of the issue


def test_defaults_round_trip_and_partial_files() -> None:
    assert flow_config_from_dict({}) == FlowConfig()
    assert load_flow_config(None) == FlowConfig()
    cfg = dataclasses.replace(FlowConfig(), warmup_s=300.0, canonical=False)
    assert flow_config_from_dict(json.loads(flow_config_json(cfg))) == cfg
    # a partial nested section keeps the *flow's* matcher defaults (450 keypoints, no slant),
    # not the standalone matcher's (2000, slant)
    part = flow_config_from_dict({"roi": {"match": {"radius": 9}}})
    assert part.roi.match == dataclasses.replace(FlowConfig().roi.match, radius=9)


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"roi": {"match": {"radiuss": 9}}}, r"roi\.match\.radiuss: Extra inputs"),
        ({"warmup_s": "soon"}, r"warmup_s: Input should be a valid number"),
        ({"roi": {"mode": "canonical"}}, r"roi\.mode: Extra inputs"),  # no second switch
        ({"roi": {"match": {"radius": 99}}}, r"radius must be an integer 2\.\.32"),
        ({"warmup_s": -1}, r"warmup_s must be >= 0"),
        ({"lookup": "closest"}, r"unknown lookup 'closest'"),
        ([1, 2], r"must be a JSON object"),
    ],
)
def test_bad_files_name_the_key(doc: object, message: str) -> None:
    with pytest.raises(InputError, match=message):
        flow_config_from_dict(doc)


def test_no_silent_overwrite_of_mode_and_wt_scale() -> None:
    # The switches exist once (FlowConfig); the ROI config carries neither, and FlowConfig
    # leaves the roi it is given as it is.
    roi = RoiConfig(expand=2.0)
    cfg = FlowConfig(canonical=False, wt_scale=False, roi=roi)
    assert cfg.roi is roi and cfg.mode == "tele-to-wide"
    assert not {"mode", "wt_scale"} & {f.name for f in dataclasses.fields(RoiConfig)}
    cam = Camera((400, 300), 500.0, 500.0, 199.5, 149.5)
    rig = Rig(cam, cam, Transform(np.eye(3), np.array([0.01, 0.0, 0.0])))
    ref = Rectification.from_rig(rig, "canonical")
    img = np.zeros((300, 400), np.uint8)
    with pytest.raises(InputError, match="mode 'tele-to-wide' but the reference is 'canonical'"):
        measure_roi(rig, img, img, (100, 100, 50, 50), roi, ref, mode="tele-to-wide")


def test_config_show_cli(tmp_path: Path) -> None:
    res = runner.invoke(app, ["config", "show"])
    assert res.exit_code == 0 and flow_config_from_dict(json.loads(res.stdout)) == FlowConfig()
    schema = json.loads(runner.invoke(app, ["config", "show", "--schema"]).stdout)
    assert "[s] Heated gate" in schema["properties"]["warmup_s"]["description"]
    path = tmp_path / "flow.json"
    path.write_text('{"warmup_s": 300}')
    res = runner.invoke(app, ["config", "show", "--config", str(path)])
    assert res.exit_code == 0 and json.loads(res.stdout)["warmup_s"] == 300.0
    path.write_text('{"warmup": 300}')
    commands = (
        ["config", "show"],
        ["learn", "x", "--calibration", "c", "--store", "s"],
        ["depth", "x", "--calibration", "c", "--store", "s"],
        ["evaluate", "x"],
        ["demo", "--out", str(tmp_path / "demo")],
        ["batch", "learn", "--inputs", "x*", "--out", str(tmp_path / "b")],
    )
    for cmd in commands:
        res = runner.invoke(app, [*cmd, "--config", str(path)])
        assert res.exit_code == 2 and "warmup: Extra inputs are not permitted" in res.output, cmd
