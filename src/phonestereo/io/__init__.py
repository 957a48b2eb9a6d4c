"""Files a user touches (DESIGN §4): capture sets, the calibration file, OpenCV YAML, images."""

from phonestereo.io.calibration import (
    Calibration,
    CalibrationConditions,
    calibration_from_dict,
    calibration_to_dict,
    load_calibration,
    save_calibration,
)
from phonestereo.io.images import read_gray, write_image
from phonestereo.io.manifest import (
    CaptureEntry,
    CaptureSet,
    Manifest,
    load_capture_set,
    parse_manifest,
    write_manifest,
)
from phonestereo.io.opencv_yaml import export_opencv_yaml, import_opencv_yaml, lens_from_opencv

__all__ = [
    "Calibration",
    "CalibrationConditions",
    "CaptureEntry",
    "CaptureSet",
    "Manifest",
    "calibration_from_dict",
    "calibration_to_dict",
    "export_opencv_yaml",
    "import_opencv_yaml",
    "lens_from_opencv",
    "load_calibration",
    "load_capture_set",
    "parse_manifest",
    "read_gray",
    "save_calibration",
    "write_image",
    "write_manifest",
]
