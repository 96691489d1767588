"""Snap a click to the centre line of the stem under it.

A stem is a thin bar darker or lighter than what surrounds it. Across such a bar the image's second
derivative (the Hessian eigenvalue of largest magnitude) peaks on the centre line, with the same sign all
along the bar; along the bar it hardly changes. :class:`RidgeSnapper` computes the scale-normalised
Hessian of each colour channel at two scales (Gaussian sigma 2.5 and 3.5 px, matched to stems about 6-12 px
wide; smaller scales answer the bark's texture), takes the strongest response per pixel, finds the strongest
ridge pixel within ``radius_px`` of the click and moves the click *across* the stem (along the Hessian's
principal direction there) onto that ridge line. The position along the stem stays where the user
clicked, so a node is not dragged to a nearby knot or fork.

Units: pixels, OpenCV convention (pixel centres at integer coordinates, x right, y down).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class SnapResult:
    """Where a click ended up.

    x, y: snapped position (px). moved_px: distance from the click (px). snapped: whether a stem was found
    within the radius (False: the click is returned unchanged).
    """

    x: float
    y: float
    moved_px: float
    snapped: bool


class RidgeSnapper:
    """Snap clicks on an RGB image (H, W, 3) uint8 to the nearest stem centre line.

    ``radius_px``: how far a click may move (px). ``sigmas``: Gaussian scales (px) of the Hessian; a bar of
    width w responds most at sigma ~ w / (2 sqrt 3). ``min_strength``: a ridge weaker than this fraction of
    the image's 99th-percentile response is not a stem (the click stays put).
    """

    def __init__(self, image: np.ndarray, radius_px: float = 6.0, sigmas: tuple[float, ...] = (2.5, 3.5),
                 min_strength: float = 0.15):
        img = np.asarray(image, dtype=np.float32)
        if img.ndim == 2:
            img = img[..., None]
        self.radius_px = float(radius_px)
        best = np.zeros(img.shape[:2], np.float32)       # strongest signed eigenvalue magnitude
        normal = np.zeros(img.shape[:2] + (2,), np.float32)  # unit vector across the bar
        for s in sigmas:
            for c in range(img.shape[2]):
                g = cv2.GaussianBlur(img[..., c], (0, 0), s)
                dxx = cv2.Sobel(g, cv2.CV_32F, 2, 0, ksize=3)
                dyy = cv2.Sobel(g, cv2.CV_32F, 0, 2, ksize=3)
                dxy = cv2.Sobel(g, cv2.CV_32F, 1, 1, ksize=3)
                half_tr = 0.5 * (dxx + dyy)
                root = np.sqrt(0.25 * (dxx - dyy) ** 2 + dxy ** 2)
                lam1, lam2 = half_tr + root, half_tr - root   # lam1 >= lam2
                big = np.where(np.abs(lam1) >= np.abs(lam2), lam1, lam2)
                resp = (s * s) * np.abs(big)
                upd = resp > best
                if not upd.any():
                    continue
                best[upd] = resp[upd]
                # eigenvector of `big`: (dxy, big - dxx), or (big - dyy, dxy) when that one is degenerate
                vx, vy = dxy, big - dxx
                alt = np.hypot(vx, vy) < 1e-6
                vx = np.where(alt, big - dyy, vx)
                vy = np.where(alt, dxy, vy)
                n = np.hypot(vx, vy)
                n[n < 1e-9] = 1.0
                normal[upd, 0] = (vx / n)[upd]
                normal[upd, 1] = (vy / n)[upd]
        self._strength = best
        self._normal = normal
        self._floor = float(min_strength) * float(np.percentile(best, 99)) if best.size else 0.0

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) pixels."""
        return self._strength.shape[1], self._strength.shape[0]

    def snap(self, x: float, y: float) -> SnapResult:
        """Move the click (x, y) (px) across the stem onto its centre line (at most ``radius_px``)."""
        W, H = self.size
        xi, yi = int(round(x)), int(round(y))
        if self.radius_px <= 0 or not (0 <= xi < W and 0 <= yi < H):
            return SnapResult(float(x), float(y), 0.0, False)
        r = int(np.ceil(self.radius_px))
        x0, x1, y0, y1 = max(0, xi - r), min(W, xi + r + 1), max(0, yi - r), min(H, yi + r + 1)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        d = np.hypot(xx - x, yy - y)
        # the strongest ridge pixel within the radius, mildly preferring pixels near the click
        score = np.where(d <= self.radius_px, self._strength[y0:y1, x0:x1] * np.exp(-0.5 * (d / 8.0) ** 2), -1.0)
        k = np.unravel_index(np.argmax(score), score.shape)
        if self._strength[y0:y1, x0:x1][k] < self._floor:
            return SnapResult(float(x), float(y), 0.0, False)
        px, py = float(xx[k]), float(yy[k])
        n = self._normal[y0:y1, x0:x1][k]
        # sub-pixel: a parabola through the response one pixel either side across the stem
        a, b, c = self._bilinear(self._strength, px + np.array([-1.0, 0.0, 1.0]) * n[0],
                                 py + np.array([-1.0, 0.0, 1.0]) * n[1])
        den = a - 2 * b + c
        u = float(np.clip(0.5 * (a - c) / den, -1, 1)) if den < 0 else 0.0
        # keep the position along the stem: move the click only across it, onto the ridge line
        t = (px + u * n[0] - x) * n[0] + (py + u * n[1] - y) * n[1]
        sx, sy = float(x + t * n[0]), float(y + t * n[1])
        return SnapResult(sx, sy, float(abs(t)), True)

    @staticmethod
    def _bilinear(a: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return cv2.remap(a, x.astype(np.float32)[None], y.astype(np.float32)[None], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE)[0]
