"""The diagnosis: evidence -> decision -> report. :func:`rce_gtsam.diagnosis.diagnose.diagnose` runs the steps:

* :mod:`.result` — the typed results (:class:`~.result.Diagnosis`, :class:`~.result.CandidateResult`, and the
  common shape of every test's result, :class:`~.result.TestResult`: statistic, p or threshold, its null, its
  calibration record); everything that needs only the types imports it;
* :mod:`.evidence` — each candidate's fit, held-out error and tests, typed, no decision; the tests, one module
  each with its design and measurements in its docstring: :mod:`.heldout` (folds, the fold-paired t),
  :mod:`.score_test` (the full-data tests), :mod:`.heldout_null` and :mod:`.drift_pattern` (what an
  offset/creep must show that tracker drift cannot), :mod:`.tracker_signature` (the same away from lost
  nodes), :mod:`.encompassing` (delay vs inertia), :mod:`.maxt` (the family-wise alternative),
  :mod:`.plausibility`, :mod:`.information` (the AIC on the effective sample);
* :mod:`.decision` — THE rule (significant, supported, verdict), with its helpers between supported candidates
  in :mod:`.verdict`; computes no statistic;
* :mod:`.explain` — the explanation and the text report (reads result types only);
* :mod:`.domain` — whether the analysis' settings are those the tests are calibrated on (else nothing is named);
  :mod:`.noise_floor`, :mod:`.budget` — the model-free noise floor and the variance budget; :mod:`.sysid` —
  residual analysis as system identification does it; :mod:`.misfit` — where the baseline fails;
  :mod:`.statistics` — the residual statistics effects compute their own evidence with; :mod:`.oracle` — the
  benchmark's ceiling; :mod:`.io` — glue to an analysis; :mod:`.settings` — the constants.

Effects own their physics, test directions and evidence (:mod:`rce_gtsam.effects`); nothing here names one.
"""
