"""Stage 2, smoothing: tracks -> smoothed node positions with marginal covariances (px, px^2).

* :mod:`.smoother` — the GTSAM factor graph (measurement, velocity, acceleration, edge factors from
  :mod:`rce_gtsam.factors`), solved by Levenberg-Marquardt window by window;
* :mod:`.marginals` — each position's marginal covariance;
* :mod:`.windowing` — overlapping frame windows for long recordings; :mod:`.memory` — handing freed heap back;
* :mod:`.presmooth` — the reference pipeline's moving-average pre-smoothing;
* :mod:`.reference` — the reference smoother the tests and benchmarks compare with.
"""
