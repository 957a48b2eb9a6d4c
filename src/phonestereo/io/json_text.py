"""Reading a user's JSON file: one wording for every parse error (file name, line, column,
what is wrong) and for a file that cannot be read."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from phonestereo.errors import InputError


def parse_json(text: str, source: str) -> Any:
    """The JSON document ``text``; :class:`InputError` ``"<source>: not valid JSON at line L
    column C: …"`` when it does not parse.

    >>> parse_json('{"a": [1, 2]}', "x.json")
    {'a': [1, 2]}
    >>> parse_json('{"a": }', "x.json")
    Traceback (most recent call last):
    ...
    phonestereo.errors.InputError: x.json: not valid JSON at line 1 column 7: Expecting value
    """
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(
            f"{source}: not valid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from exc


def read_text(path: Path, what: str, hint: str = "") -> str:
    """The UTF-8 text of file ``path``; :class:`InputError` ``"cannot read <what> <path>
    (<why>)[; <hint>]"`` when it cannot be read (missing, a folder, no permission, or not
    UTF-8: a photo or an archive picked by mistake).

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = Path(d) / "m.json"
    ...     _ = p.write_bytes(b"\\xff\\xd8\\xff")
    ...     try:
    ...         read_text(p, "module file", "pass a module JSON")
    ...     except InputError as err:
    ...         print(str(err).split(" (")[1])
    not UTF-8 text); pass a module JSON
    """
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        why = "not UTF-8 text" if isinstance(exc, UnicodeDecodeError) else exc.strerror or exc
        tail = f"; {hint}" if hint else ""
        raise InputError(f"cannot read {what} {path} ({why}){tail}") from None


def read_json(path: Path, what: str) -> Any:
    """The JSON document in file ``path`` (UTF-8); :func:`read_text`'s :class:`InputError` when
    it cannot be read, :func:`parse_json`'s (named by the file name) when
    it does not parse."""
    return parse_json(read_text(path, what), path.name)


__all__ = ["parse_json", "read_json", "read_text"]
