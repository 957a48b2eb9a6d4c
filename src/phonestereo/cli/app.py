"""The one Typer app; command modules in this package register on it, and are imported lazily.

``phonestereo --help`` and ``phonestereo version`` must start fast (≤ 0.5 s), but the command
modules import MediaPipe, Dask and SciPy (~2 s together). So the app's Click group is a
:class:`LazyGroup`: it finds each command's name, module and short help by *reading* the
command modules' source (:func:`discover`, ~40 ms for all of them, nothing imported), lists the
commands from that, and imports a command's module only when that command runs or its own
``--help`` is asked for. A new command module needs no registration here: any ``cli/*.py`` whose
functions are decorated ``@app.command(...)`` or which calls ``app.add_typer(...)`` is found.

The root ``--verbose`` flag sets ``PHONESTEREO_VERBOSE=1``; without it, the native log lines of
MediaPipe / TensorFlow Lite / absl are silenced
(:mod:`phonestereo.features.landmarks.quiet`).
"""

from __future__ import annotations

import ast
import importlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperCommand, TyperGroup

from phonestereo import __version__

_CLI_DIR = Path(__file__).resolve().parent
_NOT_COMMANDS = {"__init__", "app"}
VERBOSE_ENV = "PHONESTEREO_VERBOSE"


@dataclass(frozen=True)
class LazyCommand:
    """A command known from its module's source: name, module and short help (not imported)."""

    name: str
    module: str
    help: str


def _literal(node: ast.expr | None) -> str:
    """The value of a string-literal AST node, else '' (help text computed at import time)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    return ""


def _kw(call: ast.Call, key: str) -> ast.expr | None:
    return next((k.value for k in call.keywords if k.arg == key), None)


def _is_app_call(node: ast.AST, method: str) -> bool:
    """True for ``app.<method>(...)``."""
    return (
        isinstance(node, ast.Call)
        and isinstance(node.func, ast.Attribute)
        and node.func.attr == method
        and isinstance(node.func.value, ast.Name)
        and node.func.value.id == "app"
    )


def _first_paragraph(text: str | None) -> str:
    return (text or "").strip().split("\n\n")[0]


def commands_in(source: str, module: str) -> list[LazyCommand]:
    """The top-level commands a cli module's source registers on ``app``, in source order.

    >>> src = '''
    ... sub = typer.Typer(help="Things: list, show.")
    ... app.add_typer(sub, name="things")
    ... other = typer.Typer()
    ... @other.callback()
    ... def _other() -> None:
    ...     \"\"\"Other things.\"\"\"
    ... app.add_typer(other, name="other")
    ... @app.command("do-it")
    ... def do_it() -> None:
    ...     \"\"\"Do it.\"\"\"
    ... '''
    >>> [(c.name, c.help) for c in commands_in(src, "m")]
    [('things', 'Things: list, show.'), ('other', 'Other things.'), ('do-it', 'Do it.')]
    """
    tree = ast.parse(source)
    typers: dict[str, str] = {}  # variable name → help of `VAR = typer.Typer(help=...)`
    for node in tree.body:  # or, without help=, the docstring of its `@VAR.callback()`
        if isinstance(node, ast.FunctionDef):
            for dec in node.decorator_list:
                f = dec.func if isinstance(dec, ast.Call) else dec
                if isinstance(f, ast.Attribute) and f.attr == "callback":
                    if isinstance(f.value, ast.Name):
                        typers.setdefault(f"{f.value.id}.callback", ast.get_docstring(node) or "")
    out: list[LazyCommand] = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
            call = node.value
            if isinstance(call.func, ast.Attribute) and call.func.attr == "Typer":
                for target in node.targets:
                    if isinstance(target, ast.Name):
                        typers[target.id] = _literal(_kw(call, "help"))
        elif isinstance(node, ast.Expr) and isinstance(node.value, ast.Call):
            call = node.value
            if not _is_app_call(call, "add_typer"):
                continue
            name = _literal(_kw(call, "name"))
            var = call.args[0] if call.args else None
            help_ = _literal(_kw(call, "help"))
            if not help_ and isinstance(var, ast.Name):
                help_ = typers.get(var.id, "") or typers.get(f"{var.id}.callback", "")
            if name:
                out.append(LazyCommand(name, module, _first_paragraph(help_)))
        elif isinstance(node, ast.FunctionDef):
            for dec in node.decorator_list:
                if _is_app_call(dec, "command"):
                    assert isinstance(dec, ast.Call)
                    name = _literal(dec.args[0]) if dec.args else _literal(_kw(dec, "name"))
                    name = name or node.name.replace("_", "-")
                    help_ = _literal(_kw(dec, "help")) or ast.get_docstring(node) or ""
                    out.append(LazyCommand(name, module, _first_paragraph(help_)))
    return out


def discover(folder: Path = _CLI_DIR) -> dict[str, LazyCommand]:
    """Every command of the ``phonestereo.cli`` modules in ``folder``, by name (module order).

    Returns an empty dict when the sources are not there (an install without ``.py`` files);
    the group then imports every module (slow start, same commands).
    """
    out: dict[str, LazyCommand] = {}
    for path in sorted(folder.glob("*.py")):
        if path.stem in _NOT_COMMANDS:
            continue
        for cmd in commands_in(path.read_text(encoding="utf-8"), f"phonestereo.cli.{path.stem}"):
            out.setdefault(cmd.name, cmd)
    return out


def import_all() -> None:
    """Import every command module (registers all commands on :data:`app`)."""
    for path in sorted(_CLI_DIR.glob("*.py")):
        if path.stem not in _NOT_COMMANDS:
            importlib.import_module(f"phonestereo.cli.{path.stem}")


class LazyGroup(TyperGroup):
    """A Typer group that lists commands from :func:`discover` and imports one on first use."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy = discover()
        if not self.lazy:
            import_all()
            self.commands.update(typer.main.get_command(app).commands)  # type: ignore[attr-defined]
        self._listing = False

    def list_commands(self, ctx: Any) -> list[str]:
        return list(self.commands) + [n for n in self.lazy if n not in self.commands]

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        if cmd_name in self.commands or cmd_name not in self.lazy:
            return self.commands.get(cmd_name)
        lazy = self.lazy[cmd_name]
        if self._listing:  # the top-level help only needs the name and the short help
            return TyperCommand(cmd_name, help=lazy.help)
        importlib.import_module(lazy.module)
        built = typer.main.get_command(app)
        assert isinstance(built, TyperGroup)
        cmd = built.commands.get(cmd_name)
        if cmd is not None:
            self.commands[cmd_name] = cmd
        return cmd

    def format_help(self, ctx: Any, formatter: Any) -> None:
        self._listing = True
        try:
            super().format_help(ctx, formatter)
        finally:
            self._listing = False


app = typer.Typer(
    name="phonestereo",
    cls=LazyGroup,
    help="Metric depth from a phone's wide + tele stereo cameras (calibrate, simulate, measure).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


@app.callback()
def _root(
    verbose: Annotated[
        bool,
        typer.Option(
            "--verbose",
            "-v",
            help="Show the native log lines of MediaPipe / TensorFlow Lite (silenced otherwise).",
        ),
    ] = False,
) -> None:
    """Metric depth from a phone's wide + tele stereo cameras.

    Start with `phonestereo demo`; every command has --help. Documentation: docs/index.md.
    """
    if verbose:
        os.environ[VERBOSE_ENV] = "1"


@app.command()
def version() -> None:
    """Print the phonestereo version."""
    typer.echo(__version__)
