"""Rectification of a wide/tele pair: the thesis's three modes, for points and images.

Thesis §1.3.3 (``tele-to-wide``), §3.2 fix 2 (``undistort-both``) and §3.3 (``canonical``).
After rectification d = x_wide − x_tele > 0 in front and e = y_wide − y_tele
(docs/conventions.md); a vertical-baseline module is quarter-turned so its disparity is along x.

>>> from phonestereo.geometry import Camera, Rig, Transform
>>> wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
>>> rig = Rig(wide, wide.scaled(3.0), Transform.from_rotvec([0, 0, 0], [-0.012, 0, 0]))
>>> rect = Rectification.from_rig(rig, "undistort-both")
>>> round(rect.f_px), round(rect.baseline_m, 3), round(float(rect.depth(9.0)), 3)
(1500, 0.012, 2.0)
"""

from phonestereo.rectification.frames import (
    canonical_rotation,
    quarter_turn,
    quarter_turn_camera,
    quarter_turns_for,
    rotate_lens,
)
from phonestereo.rectification.maps import INVALID, build_map, check_pair, remap_image
from phonestereo.rectification.options import MODES, Mode, RectifyOptions, check_mode
from phonestereo.rectification.points import from_rectified, to_rectified
from phonestereo.rectification.rectify import Rectification

__all__ = [
    "INVALID",
    "MODES",
    "Mode",
    "Rectification",
    "RectifyOptions",
    "build_map",
    "canonical_rotation",
    "check_mode",
    "check_pair",
    "from_rectified",
    "quarter_turn",
    "quarter_turn_camera",
    "quarter_turns_for",
    "remap_image",
    "rotate_lens",
    "to_rectified",
]
