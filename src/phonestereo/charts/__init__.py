"""Chart layouts (thesis §1.2.2, §2.2) and their printable export.

Every planar object implements :class:`Chart` (``name``, ``size_m``, ``intensity(uv)``,
``keypoints()``) in the chart frame of :mod:`phonestereo.charts.base` (origin top-left,
u right, v down, metres, z into the chart); the renderer and the detectors use only that.
"""

from phonestereo.charts.base import (
    INK_BLACK,
    PAPER_WHITE,
    Chart,
    Keypoints,
    linear_to_srgb,
    print_to_reflectance,
    reflectance_to_print,
    srgb_to_linear,
)
from phonestereo.charts.export import PrintedChart, export_pdf, export_png, raster
from phonestereo.charts.faces import IPD_M, FaceChart, Portrait, portraits
from phonestereo.charts.texture import TexturedPlane
from phonestereo.charts.verification import (
    CIRCLE_RADIUS_SQUARES,
    Chessboard,
    CirclePair,
    VerificationChart,
)

__all__ = [
    "CIRCLE_RADIUS_SQUARES",
    "INK_BLACK",
    "IPD_M",
    "PAPER_WHITE",
    "Chart",
    "Chessboard",
    "CirclePair",
    "FaceChart",
    "Keypoints",
    "Portrait",
    "PrintedChart",
    "TexturedPlane",
    "VerificationChart",
    "export_pdf",
    "export_png",
    "linear_to_srgb",
    "portraits",
    "print_to_reflectance",
    "raster",
    "reflectance_to_print",
    "srgb_to_linear",
]
