"""GTSAM factors of the branch-track smoother (installed as ``rce_gtsam.factors``).

Every factor acts on ``gtsam.Point2`` variables (one per node and frame, pixels) and is a C++
factor (built-in or a linear container), so Levenberg-Marquardt never calls back into Python.
Each class documents its residual, exposes it as ``residual(...)`` in numpy (for tests and
diagnostics) and builds the GTSAM factor with ``create(...)``.
"""

from ._noise import MEASUREMENT_WEIGHT_FLOOR, oriented_covariance, robustify, sigma_from_weight
from .acceleration import AccelerationFactor
from .edge_length import EdgeLengthFactor
from .edge_offset import EdgeOffsetFactor
from .measurement import MeasurementFactor
from .velocity import VelocityFactor

__all__ = ["MeasurementFactor", "VelocityFactor", "AccelerationFactor", "EdgeOffsetFactor",
           "EdgeLengthFactor", "MEASUREMENT_WEIGHT_FLOOR", "oriented_covariance", "robustify",
           "sigma_from_weight"]
