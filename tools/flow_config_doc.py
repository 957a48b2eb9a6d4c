"""Regenerate the knob tables of docs/flow-config.md from the code (run after adding a knob).

A new field of FlowConfig, RoiConfig or MatchConfig needs its entry in
``src/phonestereo/flows/config_knobs.py`` (unit, meaning, why the default) first;
``tests/flows/test_config_file.py`` fails until both are done.

Usage::

    .venv/bin/python tools/flow_config_doc.py
"""

from __future__ import annotations

from pathlib import Path

from phonestereo.flows.config_file import knobs_markdown

BEGIN, END = "<!-- knobs:begin -->\n", "<!-- knobs:end -->"


def main() -> None:
    doc = Path(__file__).resolve().parents[1] / "docs" / "flow-config.md"
    text = doc.read_text()
    head, rest = text.split(BEGIN, 1)
    tail = rest[rest.index(END) :]
    doc.write_text(head + BEGIN + knobs_markdown() + tail)
    print(f"wrote {doc}")


if __name__ == "__main__":
    main()
