"""Composable bend-response model: the rank-1 compliance core plus physical effect terms.

Usage (configuration in the constructor, fitted values only in the returned :class:`ModelFit`)::

    from rce_gtsam import effects
    from rce_gtsam.model import ResponseModel
    from rce_gtsam.presets import get_preset
    fit = ResponseModel().fit(Y, weights=w, root_distance=s)          # = rce analyze's rank-1 fit (default preset)
    model = ResponseModel(config=get_preset("paper").compliance) + effects.Delay() + effects.Offset()
    fit = model.fit(Y, weights=None, root_distance=s)
    fit.kappa, fit.z, fit.params, fit.predict(), fit.residuals, fit.aic, fit.bic, print(fit.report())

Modules (imports only point down this list; nothing here imports :mod:`rce_gtsam.effects` or the diagnosis):

* :mod:`~rce_gtsam.model.response_model` — :class:`ResponseModel`: the model, ``fit`` and the public
  solver ``solve`` (warm starts, frozen parameters, ridge on z, frame multiplicities);
* :mod:`~rce_gtsam.model.steps` — the solver steps effects call: :func:`kappa_step`, :func:`z_step`,
  :func:`sse_after_z`, :func:`profiled_sse`, :func:`operator_z_solve`;
* :mod:`~rce_gtsam.model.fit` — :class:`ModelFit`, :class:`ParamValue`;
* :mod:`~rce_gtsam.model.view` — :class:`FitView` (what an effect sees during a fit), :class:`PartialView`;
* :mod:`~rce_gtsam.model.starts` — :func:`~rce_gtsam.model.starts.solve_from_starts`: a fit from every start an
  effect proposes, the one that best predicts each node-disjoint row set from the other's excitation kept;
* :mod:`~rce_gtsam.model.series` — autocorrelation and the Diebold-Mariano test of two loss series (the
  diagnosis' full-data held-out test);
* :mod:`~rce_gtsam.model.row_sets` — :func:`~rce_gtsam.model.row_sets.node_disjoint_split`: two row sets that
  share no tracked node (independent tracking noise);
* :mod:`~rce_gtsam.model.tangent` — :func:`~rce_gtsam.model.tangent.remove_rank1_tangent`: the part of a direction
  that no change of kappa or z can absorb (the diagnosis' score tests; effects preparing their test directions);
* :mod:`~rce_gtsam.model.report` — :func:`render_fit_report`;
* :mod:`~rce_gtsam.model.inputs` — :func:`validate_inputs`.

The rank-1 core itself is :mod:`rce_gtsam.model.compliance` (ALS / GLS with shrinkage of log kappa), its
bootstrap CIs :mod:`rce_gtsam.model.uncertainty`, and the phase surrogates they and the diagnosis draw
:mod:`rce_gtsam.model.surrogates`.
Units: degrees (Y, z, predictions), frames.
"""

from .fit import ModelFit, ParamValue
from .inputs import validate_inputs
from .report import render_fit_report
from .response_model import ResponseModel
from .steps import Z_RIDGE, core_step, kappa_step, operator_z_solve, profiled_sse, sse_after_z, z_step
from .view import FitView, PartialView

__all__ = ["ResponseModel", "ModelFit", "ParamValue", "FitView", "PartialView", "validate_inputs",
           "render_fit_report", "kappa_step", "z_step", "core_step", "sse_after_z", "profiled_sse",
           "operator_z_solve", "Z_RIDGE"]
