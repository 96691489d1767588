"""The diagnosis' machinery; :func:`rce_gtsam.diagnosis.diagnose.diagnose` runs it, in this order:

* :mod:`.domain` — whether the analysis' settings are those the tests are calibrated on (else nothing is
  named);
* :mod:`.noise_floor` — the angle-noise floor from what does not depend on the model (segment stretch);
* :mod:`.heldout` — folds, each model's held-out error (z from one node-disjoint row set, the other scored),
  the fold-paired t and the Diebold-Mariano test over frames;
* :mod:`.score_test` — each effect's calibrated full-data score test (phase-randomised surrogates);
* :mod:`.maxt` — the family-wise sign-flip max-T alternative;
* :mod:`.heldout_null`, :mod:`.drift_pattern` — what an offset/creep must show beyond its fold t that tracker
  drift cannot (a gain beyond phase surrogates; trends laid out otherwise than a node's drift);
* :mod:`.encompassing` — does a richer candidate predict what a simpler one leaves (delay vs inertia);
* :mod:`.verdict` — support, parsimony, the verdict;
* :mod:`.budget` — the variance budget (rank-1, effects, noise floor, unexplained);
* :mod:`.sysid` — residual analysis as system identification does it (cross-correlation, frequency response,
  cross-spectral singular values, trend, gain vs amplitude);
* :mod:`.statistics` — the residual statistics effects compute their own evidence with;
* :mod:`.explain` — the explanation and the text report (a leaf: computes nothing);
* :mod:`.oracle` — the benchmark's ceiling (true form and parameters); :mod:`.settings` — the constants.

Effects own their physics, test directions and evidence (:mod:`rce_gtsam.effects`); nothing here names one.
"""
