"""Pure geometry (no I/O): lens models, Camera, Transform, Rig, epipolar algebra, eq. (4)."""

from phonestereo.geometry.camera import Camera
from phonestereo.geometry.epipolar import (
    EssentialScales,
    epipolar_residual,
    essential_from_pose,
    essential_scales,
    fundamental_from_essential,
    skew,
)
from phonestereo.geometry.lens import LensModel
from phonestereo.geometry.lens_models import (
    LENS_MODELS,
    OpenCV5,
    OpenCV8,
    RadialOdd,
    RadialOddCentred,
    lens_from_dict,
    make_lens,
)
from phonestereo.geometry.rig import Rig
from phonestereo.geometry.stereo import (
    depth_from_disparity,
    disparity_from_depth,
    relative_depth_error,
)
from phonestereo.geometry.transform import Transform

__all__ = [
    "LENS_MODELS",
    "Camera",
    "EssentialScales",
    "LensModel",
    "OpenCV5",
    "OpenCV8",
    "RadialOdd",
    "RadialOddCentred",
    "Rig",
    "Transform",
    "depth_from_disparity",
    "disparity_from_depth",
    "epipolar_residual",
    "essential_from_pose",
    "essential_scales",
    "fundamental_from_essential",
    "lens_from_dict",
    "make_lens",
    "relative_depth_error",
    "skew",
]
