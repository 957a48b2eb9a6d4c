from typer.testing import CliRunner

from phonestereo import __version__
from phonestereo.cli import app


def test_version() -> None:
    result = CliRunner().invoke(app, ["version"])
    assert result.exit_code == 0
    assert result.output.strip() == __version__
