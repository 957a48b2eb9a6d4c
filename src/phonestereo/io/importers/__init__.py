"""Importers from phone platforms to capture sets: Android Camera2 and Apple AVFoundation dumps,
and plain EXIF JPEGs (docs/import-android.md, docs/import-apple.md, docs/import-exif.md)."""

from phonestereo.io.importers.android import import_android
from phonestereo.io.importers.common import ImportResult

__all__ = ["ImportResult", "import_android"]
