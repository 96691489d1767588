"""The diagnosis' fixed settings (constants shared by the held-out test, the candidates' fits and the oracle).

Units: frames (block length), sweeps (iteration caps), folds; ``RESOLUTION`` is a share of the bending variance.
"""

from __future__ import annotations

BLOCK_LENGTH = 25  # frames: the moving-block bootstrap's block length (reference §2.9)
FULL_ITER = 25  # block-coordinate sweeps of a candidate's fit on all frames (from the baseline fit)
#: cross-validation blocks (rce_gtsam.diagnosis.heldout explains why: the test's power is set by their number)
N_FOLDS = 16
CV_ITER = 10  # sweeps of each fold's refit and held-out z estimate (from the full fit)
RESOLUTION = 1e-3  # smallest share of the bending variance a named effect takes off the held-out MSE
