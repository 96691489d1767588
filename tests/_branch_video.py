"""A small synthetic video with known motion for the review tests: a bark-textured branch over a textured green
background, swinging rigidly about its root (so every point of the branch has a known position in every frame)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

W, H = 320, 240
ROOT = np.array([70.0, 210.0])
#: node positions in frame 0 (px): a chain from the root up and to the right
NODES = np.array([ROOT, [100.0, 176.0], [132.0, 142.0], [164.0, 108.0], [196.0, 74.0]])


def angle(f: int) -> float:
    """The branch's rotation about the root in frame ``f`` (rad): a sway of +-0.12 rad, period 24 frames."""
    return 0.12 * np.sin(2 * np.pi * f / 24)


def rotate(points: np.ndarray, theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    d = np.asarray(points, float) - ROOT
    return ROOT + d @ np.array([[c, -s], [s, c]])  # as cv2.getRotationMatrix2D(ROOT, degrees(theta))


def true_positions(points: np.ndarray, n_frames: int) -> np.ndarray:
    """(P, F, 2) px: where the branch points ``points`` (frame-0 px) are in each frame."""
    return np.stack([rotate(points, angle(f)) for f in range(n_frames)], axis=1)


def write_video(path: Path, n_frames: int = 36, seed: int = 0) -> Path:
    """Write the clip (mp4v, 30 fps) and return its path."""
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.normal(0, 1, (H, W)).astype(np.float32), (0, 0), 5)
    bg = np.clip(np.dstack([90 + 45 * noise, 125 + 45 * noise, 95 + 35 * noise]), 0, 255).astype(np.float32)
    bark = cv2.GaussianBlur(rng.normal(0, 1, (H, W)).astype(np.float32), (0, 0), 1.6)
    bark = 1.0 + 0.9 * bark / bark.std()
    mask = np.zeros((H, W), np.float32)
    for a, b in zip(NODES[:-1], NODES[1:]):
        cv2.line(mask, tuple(int(round(v * 16)) for v in a), tuple(int(round(v * 16)) for v in b), 1.0, 11,
                 cv2.LINE_AA, shift=4)
    layer = np.dstack([45 * bark, 75 * bark, 115 * bark]).clip(0, 255).astype(np.float32)  # BGR brown bark
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 30, (W, H))
    for f in range(n_frames):
        m = cv2.getRotationMatrix2D((float(ROOT[0]), float(ROOT[1])), float(np.degrees(angle(f))), 1.0)
        lw = cv2.warpAffine(layer, m, (W, H), flags=cv2.INTER_LINEAR)
        mw = cv2.warpAffine(mask, m, (W, H), flags=cv2.INTER_LINEAR)[..., None]
        writer.write(np.clip(mw * lw + (1 - mw) * bg, 0, 255).astype(np.uint8))
    writer.release()
    return path
