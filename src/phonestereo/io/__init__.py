"""Files a user touches (docs/capture-set.md, docs/calibration.md): capture sets, the calibration
file, OpenCV YAML, images."""

from phonestereo.io.calibration import (
    Calibration,
    CalibrationConditions,
    calibration_from_dict,
    calibration_to_dict,
    load_calibration,
    save_calibration,
)
from phonestereo.io.images import image_size, read_gray, size_mismatch, write_image
from phonestereo.io.manifest import (
    CaptureEntry,
    CaptureSet,
    Manifest,
    load_capture_set,
    parse_manifest,
    write_manifest,
)
from phonestereo.io.opencv_yaml import (
    YamlImport,
    export_opencv_yaml,
    import_opencv_yaml,
    lens_from_opencv,
    read_opencv_yaml,
)

__all__ = [
    "Calibration",
    "CalibrationConditions",
    "CaptureEntry",
    "CaptureSet",
    "Manifest",
    "YamlImport",
    "calibration_from_dict",
    "calibration_to_dict",
    "export_opencv_yaml",
    "image_size",
    "import_opencv_yaml",
    "lens_from_opencv",
    "load_calibration",
    "load_capture_set",
    "parse_manifest",
    "read_gray",
    "read_opencv_yaml",
    "save_calibration",
    "size_mismatch",
    "write_image",
    "write_manifest",
]
