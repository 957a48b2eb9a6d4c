"""``phonestereo config show``: the flow configuration's knobs and defaults (``--config``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from phonestereo.cli.app import app
from phonestereo.cli.widgets import error_exit, flag
from phonestereo.errors import InputError
from phonestereo.flows.config_file import flow_config_json, flow_config_schema, load_flow_config

config_app = typer.Typer(
    help="The flow configuration (--config FLOW.json of learn, depth, evaluate, demo, batch).",
    no_args_is_help=True,
)
app.add_typer(config_app, name="config")


@config_app.command("show")
def show(
    config: Annotated[
        Path | None,
        typer.Option(
            "--config", help="Show this file's effective configuration (defaults filled in)."
        ),
    ] = None,
    schema: Annotated[
        bool, flag("--schema", "Print the JSON schema: every knob's unit, meaning and default.")
    ] = False,
) -> None:
    """Print the flow configuration as JSON: the defaults, or a --config file's effective
    values. Save it, edit the knobs you need (any subset may be kept) and pass it with
    --config; docs/flow-config.md explains every knob.

    Example: phonestereo config show > flow.json
    """
    if schema:
        typer.echo(json.dumps(flow_config_schema(), indent=1, ensure_ascii=False))
        return
    try:
        cfg = load_flow_config(config)
    except InputError as exc:
        raise error_exit(exc) from exc
    typer.echo(flow_config_json(cfg))
