"""Running the CLI in-process for the bad-input tests (``tests/cli/test_cli_bad_inputs*.py``)."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from phonestereo.cli import app


def run(*args: str) -> tuple[int, str]:
    """``phonestereo ARGS`` in-process: the exit code and the output (stdout and stderr) as
    single-spaced words (Rich boxes and wraps long messages: tests compare on the words)."""
    res = CliRunner().invoke(app, list(args))
    return res.exit_code, " ".join(res.output.replace("│", " ").split())


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes: equal before and after = nothing modified."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def stamp(path: Path) -> tuple[bytes, int]:
    """A file's bytes and modification time (ns): equal before and after = left untouched."""
    return path.read_bytes(), path.stat().st_mtime_ns
