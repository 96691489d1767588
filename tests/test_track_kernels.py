"""The default tracker's compiled kernels (``rce_gtsam.track.match_kernels``) against the OpenCV operations they
replace, on random images, and the tracker built on them against the true node positions of a rendered clip.

If a kernel drifts from OpenCV's arithmetic (a wrong weighting, an off-by-one crop, a border mistake) these fail
before any accuracy figure moves."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from rce_gtsam.track import LKTracker, match_kernels as mk
from rce_gtsam.track.kernels_match import band_rows

from track_fixtures import rendered_simulation


@pytest.fixture
def rng():
    return np.random.default_rng(0)


@pytest.mark.parametrize("k, density", [(37, 1.0), (37, 0.5), (23, 0.3), (55, 0.9)])
def test_weighted_ncc_is_opencv_masked_ccoeff_normed(rng, k, density):
    img = rng.uniform(0, 255, (k, k)).astype(np.float32)
    tmpl = rng.uniform(0, 255, (19, 19)).astype(np.float32)
    # band-like weights: zeros, ones and anti-aliased edges
    wts = ((rng.uniform(0, 1, (19, 19)) < density) * rng.choice([0.3, 1.0], (19, 19))).astype(np.float32)
    ref = cv2.matchTemplate(img, tmpl, cv2.TM_CCOEFF_NORMED, mask=wts)
    np.testing.assert_allclose(mk.weighted_ncc(img, tmpl, wts), ref, atol=1e-5)


def test_weighted_ncc_finds_a_planted_template(rng):
    img = rng.uniform(0, 255, (37, 37)).astype(np.float32)
    tmpl = img[11:30, 5:24].copy()
    res = mk.weighted_ncc(img, tmpl, np.ones_like(tmpl))
    assert np.unravel_index(np.argmax(res), res.shape) == (11, 5) and res.max() == pytest.approx(1.0, abs=1e-6)


def test_segment_ncc_samples_like_remap(rng):
    img = cv2.GaussianBlur(rng.integers(0, 256, (120, 160)).astype(np.uint8), (0, 0), 1.5)
    uu = np.arange(0.0, 21.0, dtype=np.float32)
    vv = np.arange(-4.0, 5.0, dtype=np.float32)
    st = rng.normal(size=(9, 21)).astype(np.float32)
    st = (st - st.mean()) / np.sqrt(((st - st.mean()) ** 2).sum())
    ang = np.linspace(-0.7, 0.7, 57)
    ex, ey = np.cos(ang).astype(np.float32), np.sin(ang).astype(np.float32)
    for x0, y0 in [(80.3, 60.7), (3.2, 2.9)]:  # inside, and reaching over the border (replicated)
        mx = (np.multiply.outer(ex, uu)[:, None, :] - np.multiply.outer(ey, vv)[:, :, None]).reshape(-1, 21)
        my = (np.multiply.outer(ey, uu)[:, None, :] + np.multiply.outer(ex, vv)[:, :, None]).reshape(-1, 21)
        smp = cv2.remap(img, mx + np.float32(x0), my + np.float32(y0), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE).reshape(len(ang), -1).astype(np.float64)
        smp -= smp.mean(axis=1, keepdims=True)
        ref = smp @ st.ravel() / (np.sqrt((smp * smp).sum(axis=1)) + 1e-6)
        # equal but for a sample that lands on a rounding tie (x.5 to float precision): +-1 grey level there
        np.testing.assert_allclose(mk.segment_ncc(img, x0, y0, ex, ey, uu, vv, st, True), ref, atol=2e-3)


def _stem_image(rng, angle: float, width: float = 3.0):
    """A 160x120 textured background with a bright stem from (60, 70) at ``angle`` (radians), blurred, as uint8."""
    img = rng.integers(60, 140, (120, 160)).astype(np.float32)
    yy, xx = np.mgrid[0:120, 0:160]
    along = (xx - 60) * math.cos(angle) + (yy - 70) * math.sin(angle)
    across = -(xx - 60) * math.sin(angle) + (yy - 70) * math.cos(angle)
    img[(np.abs(across) < width / 2) & (along > -3) & (along < 45)] = 230
    return cv2.GaussianBlur(img, (0, 0), 1.0).astype(np.uint8)


def test_segment_search_coarse_to_fine_finds_the_exhaustive_peak(rng):
    """The segment search evaluates every third rotation and climbs from the two best (``stride`` 3, the
    default): it must find the rotation, the child's position and the peak the exhaustive search (``stride`` 1)
    finds, which is numpy's argmax of :func:`segment_ncc` refined by a parabola. A stem of 3 px and one of 1.5 px
    turned by random angles, searched from random priors within the span."""
    ln, h = 30.0, 8
    uu = np.arange(0.0, ln + 0.5, 1.0, dtype=np.float32)
    vv = np.arange(-2.0, 3.0, dtype=np.float32)
    span, step = math.atan2(2 * h, ln), 0.5 / ln
    offs = np.arange(-span, span + step / 2, step)
    for width in (3.0, 1.5):
        ref = _stem_image(rng, 0.0, width)
        mx = (60 + uu[None, :] + 0 * vv[:, None]).astype(np.float32)
        my = (70 + 0 * uu[None, :] + vv[:, None]).astype(np.float32)
        st = cv2.remap(ref, mx, my, cv2.INTER_LINEAR).astype(np.float32)
        st = (st - st.mean()) / np.sqrt(((st - st.mean()) ** 2).sum())
        for _ in range(25):
            turn = rng.uniform(-0.3, 0.3)
            img = _stem_image(np.random.default_rng(1), turn, width)
            prior = turn + rng.uniform(-0.8, 0.8) * span
            args = (img, 60.0, 70.0, prior, offs, 0.0, step, ln, 0.0, uu, vv, st, True)
            exhaustive, fast = mk.segment_search(*args, 1), mk.segment_search(*args, 3)
            assert fast == exhaustive
            ang = prior + offs
            ncc = mk.segment_ncc(img, 60.0, 70.0, np.cos(ang).astype(np.float32), np.sin(ang).astype(np.float32),
                                 uu, vv, st, True)
            k = int(np.argmax(ncc))
            assert exhaustive[3] == ncc[k] and abs(exhaustive[2] - ang[k]) <= step / 2 + 1e-12
            if abs(turn - prior) < span - 2 * step:  # the stem within the searched rotations: found
                assert exhaustive[2] == pytest.approx(turn, abs=1.5 * step)


def test_articulated_template_is_warp_affine_composite(rng):
    """Two segments' bands rotated by their own angles about the node, composited by weight."""
    gray = cv2.GaussianBlur(rng.integers(0, 256, (100, 100)).astype(np.uint8), (0, 0), 1.0)
    h, margin = 6, 2
    bs, k = 6 * h + 1, 2 * (h + margin) + 1
    bands = np.zeros((2, bs, bs), np.float32)
    bands[0, :, :bs // 2 + 3] = 1.0  # parent side
    bands[1, :, bs // 2 - 3:] = 0.5  # child side, overlapping
    px, py, thetas = 50.4, 47.8, np.array([0.2, -0.35])
    c, cs = (k - 1) / 2, (bs - 1) / 2
    acc = np.zeros((k, k), np.float32)
    wacc = np.zeros((k, k), np.float32)
    imgs = []
    for s, th in enumerate(thetas):
        a, b = math.cos(th), -math.sin(th)
        m_img = np.array([[a, b, (1 - a) * px - b * py + c - px], [-b, a, b * px + (1 - a) * py + c - py]])
        m_band = np.array([[a, b, (1 - a) * cs - b * cs + c - cs], [-b, a, b * cs + (1 - a) * cs + c - cs]])
        im = cv2.warpAffine(gray, m_img, (k, k), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        w = cv2.warpAffine(bands[s], m_band, (k, k), flags=cv2.INTER_LINEAR, borderValue=0)
        acc += w * im
        wacc += w
        imgs.append(im)
    ref = np.where(wacc > 1e-3, acc / np.maximum(wacc, 1e-3), imgs[0])
    rows = band_rows(bands)
    crop, tmpl, wts, wsum = mk.articulated_template(gray, px, py, thetas, bands, rows, 0, 0.0, h, margin, True)
    assert np.abs(crop - ref).max() <= 1.0 + 1e-4 and np.mean(np.abs(crop - ref) > 0.01) < 0.01  # rounding ties
    np.testing.assert_allclose(wts, np.minimum(wacc, 1)[margin:-margin, margin:-margin], atol=1e-4)
    np.testing.assert_array_equal(tmpl, crop[margin:-margin, margin:-margin])
    assert wsum == pytest.approx(float(wts.sum()), rel=1e-5)
    *_, wts_full, n = mk.articulated_template(gray, px, py, thetas, bands, rows, 0, 1e9, h, margin, True)
    assert (wts_full == 1).all() and n == (2 * h + 1) ** 2  # too few band pixels: the full patch


def test_match_node_recovers_a_subpixel_shift(rng):
    """A smooth texture shifted by (1.3, -0.6) px: the match, its forward-backward error and peak score."""
    big = cv2.GaussianBlur(rng.uniform(0, 255, (80, 80)).astype(np.float32), (0, 0), 2.0)
    h, r, margin = 9, 9, 2
    k, kp = 2 * (h + r) + 1, 2 * (h + margin) + 1
    centre = (40.0, 40.0)
    prev = cv2.getRectSubPix(big, (kp, kp), centre)
    tmpl = prev[margin:margin + 2 * h + 1, margin:margin + 2 * h + 1].copy()
    cur = cv2.getRectSubPix(big, (k, k), (centre[0] - 1.3, centre[1] + 0.6))  # node at +1.3, -0.6 from centre
    m = mk.match_node(cur, tmpl, np.ones_like(tmpl), prev, r, h, float(h + margin))
    assert m[0] == 1 and m[3] > 0.95  # integer-pixel peak of a shift with a fractional part
    assert m[1] - (h + r) == pytest.approx(1.3, abs=0.02) and m[2] - (h + r) == pytest.approx(-0.6, abs=0.02)
    assert m[4] < 0.05  # forward-backward closes


@pytest.mark.slow  # ~10-15 s, most of it rendering the clip
def test_tracker_accuracy_on_a_rendered_clip(tmp_path):
    """Simulator seed 0, 20 nodes, 60 frames of the 640x480 H.264 render, default tracker. Measured: median error
    of visible points 0.0505 px, 90th percentile 0.173 px, 93.25 % of point-frames visible -- the 7f3b223 tracker
    (before the compiled kernels) on this clip: median 0.0506 px, 93.25 %. A kernel off by a pixel or a wrong
    weighting moves the median to tenths of a pixel."""
    from rce_gtsam.sim.simulate import SimulationConfig
    from rce_gtsam.track import open_video

    sim, video, truth = rendered_simulation(tmp_path, SimulationConfig(n_nodes=20, n_frames=60, seed=0))
    with open_video(video) as src:
        res = LKTracker().track(src, truth[:, 0], sim.graph)
    err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))[res.visible]
    assert np.median(err) < 0.06
    assert np.percentile(err, 90) < 0.25
    assert res.visible.mean() > 0.92


def test_kernel_modules_record_the_digest_of_every_kernel_file_they_call_into():
    """numba's cache checks only a compiled function's own source file (numba issue 1833): were ``match_node`` in
    kernels_match.py to keep its cached machine code after an edit of ``weighted_lk`` in kernels_sampling.py, the
    tracker would run the old LK while the kernel's own test ran the new one. So every kernel module that imports
    from another records that file's digest (``CALLS_INTO``): an edit there fails this test until the digest, and so
    the calling module's file (which makes numba recompile it), is updated."""
    import hashlib
    import importlib
    import re
    from pathlib import Path

    here = Path(mk.__file__).parent
    for path in sorted(here.glob("kernels_*.py")):
        imports = set(re.findall(r"^from \.(kernels_\w+) import", path.read_text(), flags=re.M))
        module = importlib.import_module(f"rce_gtsam.track.{path.stem}")
        recorded = getattr(module, "CALLS_INTO", {})
        assert set(recorded) == {f"{name}.py" for name in imports}, f"{path.name}: CALLS_INTO must list {sorted(imports)}"
        for name, digest in recorded.items():
            now = hashlib.sha256((here / name).read_bytes()).hexdigest()[:16]
            assert digest == now, (f"{name} changed: set CALLS_INTO[{name!r}] = {now!r} in {path.name} (so numba "
                                   f"recompiles its cached kernels, which call into {name})")
