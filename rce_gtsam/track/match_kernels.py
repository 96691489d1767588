"""Compiled inner loops of the default tracker's measurement against frame 0 (numba, compiled once and cached).

At 20 nodes the tracker's time went to the per-call overhead of small numpy/OpenCV operations (a dozen
array calls per Lucas-Kanade iteration, two per template pixel sum) and to OpenCV's masked
``matchTemplate``, which goes through several DFT correlations for a 19x19 result. These kernels do the
same arithmetic in one compiled call per node, on the crops the tracker cuts with OpenCV:

* :func:`weighted_ncc` -- ``cv2.matchTemplate(img, tmpl, cv2.TM_CCOEFF_NORMED, mask=wts)``: the zero-mean
  normalised correlation with OpenCV's weighting (template mean weighted by ``wts``, products weighted by
  ``wts**2``), summed directly over the template pixels of non-zero weight; -1 where the image window has no
  variance (OpenCV: NaN, which the tracker mapped to -1).
* :func:`weighted_lk` -- the weighted, gain/bias-compensated inverse-compositional Lucas-Kanade of
  ``lk.py`` (template gradients by the 3x3 Sobel with reflect-101 borders, scale 1/8, as ``cv2.Sobel``;
  patches sampled bilinearly with replicated borders, as ``cv2.getRectSubPix``).
* :func:`match_node` -- one node's measurement: correlation peak and the best peak outside h/2 of it,
  parabolic sub-pixel peak, forward LK from it and the forward-backward error (the matched patch searched
  for in the frame-0 crop).
* :func:`segment_search` -- the segment search: :func:`segment_ncc` of the frame-0 strip over the rotations
  around the last one, the best by a parabola, and the child's position there.
* :func:`chromaticity`, :func:`chroma_mask` -- the frame-0 colour mask's per-pixel float32 arithmetic, as numpy
  does it (equal arrays).

All positions are in pixels of the crop passed in (pixel centres at integers). Results equal the
OpenCV/numpy implementation they replace to float rounding (float64 sums instead of OpenCV's float32).
Taps known to lie inside an array (checked once per call) index it through unsigned flat offsets: numba then
emits no negative-index wraparound code per tap (the same taps and arithmetic; 1.1-1.2x).
Every kernel releases the GIL (``nogil``): the tracker's refinement thread matches while the first pass does.

This module is the kernels' one import path (the tracker's ``self._kernels``); they live in one module per job:
:mod:`~rce_gtsam.track.kernels_sampling` (bilinear sampling, :func:`sample_patch`, :func:`weighted_lk`),
:mod:`~rce_gtsam.track.kernels_match` (:func:`weighted_ncc`, :func:`match_node`, :func:`articulated_template`,
:func:`match_articulated`), :mod:`~rce_gtsam.track.kernels_segment` (:func:`segment_ncc`, :func:`segment_search`)
and :mod:`~rce_gtsam.track.kernels_colour` (:func:`chromaticity`, :func:`chroma_mask`). Each is compiled with
``cache=True``, and numba's cache checks only a function's own source file (numba issue 1833): a kernel module
that calls into another records that file's digest (``CALLS_INTO``), so an edit there changes it too and its
cached kernels are recompiled (``tests/test_track_kernels.py`` checks the digests).
"""

from __future__ import annotations

from .kernels_colour import chroma_mask, chromaticity
from .kernels_match import articulated_template, match_articulated, match_node, weighted_ncc
from .kernels_sampling import sample_patch, weighted_lk
from .kernels_segment import segment_ncc, segment_search

__all__ = ["sample_patch", "weighted_lk", "weighted_ncc", "match_node", "articulated_template", "match_articulated",
           "segment_ncc", "segment_search", "chromaticity", "chroma_mask", "compiled_on_this_machine", "kernels_called"]


def kernels_called(with_graph: bool = True, colour_mask: bool = True) -> tuple:
    """The kernels a default track calls from Python on every clip (each compiles its callees into its own cached
    code): with a branch graph (and ``LKConfig.mask_to_branch``) the articulated match and the segment search, plus the
    colour mask's two (``LKConfig.mask_off_colour``); without one the whole-patch match. ``match_node`` is also a
    fallback of the graph path, compiled on its first use there."""
    if not with_graph:
        return (match_node,)
    return (match_articulated, segment_search) + ((chromaticity, chroma_mask) if colour_mask else ())


def compiled_on_this_machine(kernels: tuple | None = None) -> bool:
    """Whether numba's cache already holds compiled code, for its current source, of every kernel in ``kernels``
    (default: :func:`kernels_called` of a default track with a graph). When not, the first track that calls them
    compiles them (tens of seconds; the CLI says so first). Reads numba's cache index (``FunctionCache``; an index
    written for an older source counts as none); True where that cannot be read (numba's internals changed): then
    nothing is announced."""
    try:
        return all(bool(k._cache._cache_file._load_index()) for k in (kernels or kernels_called()))
    except Exception:  # noqa: BLE001 -- private numba API: never let a progress note break tracking
        return True
