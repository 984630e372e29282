"""Photogrammetric orientation: the mathematics of the APY.

Conventions (axes, omega-phi-kappa order and sense, sign of c, the elements
``a_ij``) are stated once, in :mod:`apygis.orient.rotation`. Ground
coordinates are metres, photo coordinates and principal distances
millimetres, tablet coordinates millimetres, angles radians.

This package imports nothing of apygis but :mod:`apygis.errors`.

Modules
-------
rotation       omega-phi-kappa matrices, their inverse and derivatives
collinearity   collinearity (a), superposition (b), APY parallax conditions (c)
transforms     map orientation: conformal, affine, bilinear tablet -> ground
height         residual height correction dpZ = A x + B y + C x y + D
photo          photo orientation by the APY parallax conditions
resection      space resection (6 parameters, collinearity)
intersection   space intersection (2 or more photos)
relative       dependent relative orientation (coplanarity, 5 parameters)
absolute       absolute orientation (7-parameter 3-D similarity)
realtime       the real-time loop and the motor calibration
io             the orientation file (JSON)
readers        the text input files (control, measurements, photo file)
lsq            the least-squares core (dense Gauss-Newton; the bundle adjustment builds on it)
"""

from apygis.orient.absolute import (
    AbsoluteOrientationResult,
    Similarity3D,
    absolute_orientation,
    similarity_closed_form,
)
from apygis.orient.collinearity import (
    ExteriorOrientation,
    InteriorOrientation,
    ground_to_photo,
    parallax,
    photo_to_ground,
    superposition,
)
from apygis.orient.height import HeightCorrection, HeightCorrectionFit, fit_height_correction
from apygis.orient.intersection import IntersectionResult, intersect
from apygis.orient.io import Orientation, load_orientation, save_orientation
from apygis.orient.photo import (
    PhotoOrientation,
    PhotoOrientationResult,
    approximate_orientation,
    orient_photo,
    photo_scale_number,
)
from apygis.orient.realtime import (
    MotorCalibration,
    RealtimeLoop,
    calibrate_plates,
    calibrate_stage,
    map_to_photo_scale,
)
from apygis.orient.relative import RelativeOrientationResult, relative_orientation
from apygis.orient.resection import ResectionResult, resect
from apygis.orient.rotation import angles_from_matrix, rotation_derivatives, rotation_matrix
from apygis.orient.transforms import (
    AffineTransform,
    BilinearTransform,
    ConformalTransform,
    MapOrientation,
    fit_map_transform,
    transform_from_dict,
)

__all__ = [
    "AbsoluteOrientationResult",
    "AffineTransform",
    "BilinearTransform",
    "ConformalTransform",
    "ExteriorOrientation",
    "HeightCorrection",
    "HeightCorrectionFit",
    "InteriorOrientation",
    "IntersectionResult",
    "MapOrientation",
    "MotorCalibration",
    "Orientation",
    "PhotoOrientation",
    "PhotoOrientationResult",
    "RealtimeLoop",
    "RelativeOrientationResult",
    "ResectionResult",
    "Similarity3D",
    "absolute_orientation",
    "angles_from_matrix",
    "approximate_orientation",
    "calibrate_plates",
    "calibrate_stage",
    "fit_height_correction",
    "fit_map_transform",
    "ground_to_photo",
    "intersect",
    "load_orientation",
    "map_to_photo_scale",
    "orient_photo",
    "parallax",
    "photo_scale_number",
    "photo_to_ground",
    "relative_orientation",
    "resect",
    "rotation_derivatives",
    "rotation_matrix",
    "save_orientation",
    "similarity_closed_form",
    "superposition",
    "transform_from_dict",
]
