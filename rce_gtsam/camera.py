"""Pinhole camera intrinsics shared by the simulator, the RealSense reader/writer and the 3-D smoother.

Coordinates: image ``u`` right, ``v`` down (px); camera frame ``x`` right, ``y`` down, ``z`` forward along the
optical axis (mm). No lens distortion (the D435i colour stream is published with zero Brown-Conrady coefficients,
and the simulator renders an ideal pinhole).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of one stream.

    width, height: image size (px). fx, fy: focal lengths (px). cx, cy: principal point (px).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def d435i_colour(cls) -> "CameraIntrinsics":
        """The D435i-like colour stream of the issue #39 simulator: 640x480, fx = fy = 615 px, centre (320, 240)."""
        return cls(640, 480, 615.0, 615.0, 320.0, 240.0)

    @classmethod
    def coerce(cls, value: "CameraIntrinsics | Mapping") -> "CameraIntrinsics":
        """Accept an instance or a mapping with keys width, height, fx, fy, cx, cy (e.g. from JSON)."""
        if isinstance(value, cls):
            return value
        try:
            return cls(int(value["width"]), int(value["height"]), float(value["fx"]), float(value["fy"]),
                       float(value["cx"]), float(value["cy"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"camera intrinsics need width, height, fx, fy, cx, cy; got {value!r} ({exc})") from None

    def to_dict(self) -> dict:
        return asdict(self)

    def project(self, xyz_mm: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) mm -> pixels (..., 2)."""
        p = np.asarray(xyz_mm, float)
        z = p[..., 2]
        return np.stack([self.fx * p[..., 0] / z + self.cx, self.fy * p[..., 1] / z + self.cy], axis=-1)

    def deproject(self, uv_px: np.ndarray, z_mm: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) and depth along the optical axis (...) mm -> camera-frame points (..., 3) mm
        (the pinhole form of ``rs2_deproject_pixel_to_point`` for a distortion-free stream)."""
        uv = np.asarray(uv_px, float)
        z = np.asarray(z_mm, float)
        return np.stack([(uv[..., 0] - self.cx) / self.fx * z, (uv[..., 1] - self.cy) / self.fy * z, z], axis=-1)
