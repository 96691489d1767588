"""GTSAM factors of the branch-track smoother (installed as ``rce_gtsam.factors``).

Every factor acts on **frame states** (one ``2N`` vector of node positions per frame, pixels; see
:mod:`rce_gtsam.factors._frame`). Linear factors are C++ ``LinearContainerFactor``s; the two
non-linear options (rest length, robust loss) are one Python ``CustomFactor`` per frame.
Each class documents its residual per node, exposes it as ``residual(...)`` in numpy (for tests and
diagnostics) and builds the GTSAM factor for one frame (or frame pair / triple) with ``create(...)``.
"""

from ._frame import KEY_CHAR, frame_key, node_columns, zero_values
from ._noise import MEASUREMENT_WEIGHT_FLOOR, ROBUST_LOSSES, oriented_covariance, sigma_from_weight
from .acceleration import AccelerationFactor
from .edge_length import EdgeLengthFactor
from .edge_offset import EdgeOffsetFactor
from .measurement import MeasurementFactor, RobustLoss
from .velocity import VelocityFactor

__all__ = ["MeasurementFactor", "VelocityFactor", "AccelerationFactor", "EdgeOffsetFactor",
           "EdgeLengthFactor", "RobustLoss", "MEASUREMENT_WEIGHT_FLOOR", "ROBUST_LOSSES", "KEY_CHAR",
           "frame_key", "node_columns", "zero_values", "oriented_covariance", "sigma_from_weight"]
