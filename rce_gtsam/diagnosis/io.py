"""Glue between an analysis and the model diagnosis: run it, write it, draw it.

* :func:`parse_effect_names` — ``"delay,offset"`` (CLI) or a sequence -> validated effect names;
  an unknown name is an :class:`~rce_gtsam.errors.InputError` listing the valid ones.
* :func:`diagnose_result` — :func:`rce_gtsam.diagnosis.diagnose.diagnose` on an
  :class:`~rce_gtsam.pipeline.AnalysisResult`'s bend-response matrix, with the preset's settings.
* :func:`diagnosis_json` — the JSON object ``rce diagnose`` / ``rce run`` write (``Diagnosis.as_dict()``
  plus the inputs).
* :func:`diagnosis_for_viz` — the mapping the figure and Rerun writers (:mod:`rce_gtsam.viz`) read:
  the JSON object plus the (edges x frames) baseline residual matrix in degrees, the frame and edge of
  each row/column, the verdict model's prediction (for before/after curves) and the text report.
* :func:`write_json_atomic` — write JSON through a temporary file and a rename.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError


def effect_names() -> tuple[str, ...]:
    """The candidate effect names, in the order the diagnosis tries them."""
    from ..effects import names
    return names()


def parse_effect_names(effects: str | Sequence[str] | None, source: str = "--effects") -> tuple[str, ...] | None:
    """Validated effect names from ``"a,b"`` or a sequence; None/empty string -> None (all candidates).

    Duplicates are dropped (first occurrence kept). Unknown names raise :class:`InputError` naming the
    valid ones.
    """
    if effects is None:
        return None
    if isinstance(effects, str):
        names = [n.strip() for n in effects.split(",") if n.strip()]
        if not names:
            return None
    else:
        names = [str(n).strip() for n in effects]
        if not names:
            return ()  # nothing to check: the effect classes (scipy.signal, ~1 s) stay unimported
    valid = effect_names()
    bad = [n for n in names if n not in valid]
    if bad:
        raise InputError(source, f"unknown effect name(s) {', '.join(repr(b) for b in bad)}; "
                                 f"valid names: {', '.join(valid)}")
    return tuple(dict.fromkeys(names))


def diagnose_inputs(result, effects=None, seed: int = 0, n_folds: int | None = None,
                    respect_domain: bool = True) -> dict:
    """The keyword arguments of :func:`rce_gtsam.diagnosis.diagnose.diagnose` for an analysis ``result``:
    ``result.response`` (Y in degrees, inverse-variance weights when the preset's compliance fit is weighted,
    normalised root distance, edge labels ``"joint->child"``, video frame of each column), the preset's block
    length and whole compliance config (so the baseline is the rank-1 fit ``rce analyze`` reports), the noise
    floor, and the preset's settings the diagnosis is not calibrated for
    (:func:`~rce_gtsam.diagnosis.domain.settings_outside_domain`; left out with ``respect_domain=False``, which
    only the benchmark that measures them uses). Other arguments as :func:`diagnose_result`."""
    from .domain import settings_outside_domain
    from .noise_floor import noise_floor_of

    names = parse_effect_names(effects, source="effects")
    resp, cfg = result.response, result.preset.compliance
    kw = {} if n_folds is None else {"n_folds": int(n_folds)}
    from ..effects import CANDIDATES
    return dict(Y=resp.Y, weights=resp.weights if cfg.weighted else None, root_distance=resp.root_distance,
                # each candidate as it reads this recording (Effect.for_analysis: the lengths, for one)
                effects=[CANDIDATES[n].for_analysis(result) for n in (effect_names() if names is None else names)],
                seed=int(seed),
                block_length=cfg.block_length, config=cfg,
                edge_labels=resp.edge_labels, frames=resp.frames,
                edge_nodes=result.bending.nodes_of(resp.bend_rows),
                node_sensitivity=node_sensitivity_of(result),
                noise_floor=noise_floor_of(result),
                outside_domain=settings_outside_domain(result.preset) if respect_domain else (), **kw)


def node_sensitivity_of(result) -> dict | None:
    """{node id: (E, 2) deg of each analysed bend per px of that node's displacement in x and y} at the rest pose
    (:func:`~rce_gtsam.diagnosis.one_node.bend_jacobian`), for the one-node check; None where a segment has no
    length."""
    from .noise_floor import rest_positions
    from .one_node import bend_jacobian

    triples = [tuple(t) for t in result.bending.nodes_of(result.response.bend_rows)]
    return bend_jacobian(triples, rest_positions(result, triples))


def diagnosis_baseline(result, seed: int = 0):
    """(baseline fit, node-disjoint row sets or None) that :func:`diagnose_result` starts from for an analysis
    ``result``: the rank-1 model on :func:`diagnose_inputs` (the preset's weights and compliance config), and
    the split of its rows that share no tracked node (edge-split ``seed``), as
    :func:`rce_gtsam.diagnosis.diagnose.diagnose` makes them. For the benchmarks that ask one test of an
    analysis without running the whole diagnosis."""
    from ..model import ResponseModel, validate_inputs
    from ..model.row_sets import node_disjoint_split, shared_node_matrix

    resp, cfg = result.response, result.preset.compliance
    Y, W, s = validate_inputs(resp.Y, resp.weights if cfg.weighted else None, resp.root_distance)
    nodes = result.bending.nodes_of(resp.bend_rows)
    return (ResponseModel(config=cfg).solve(Y, W, s),
            node_disjoint_split(s, shared_node_matrix(s, nodes), seed, edge_nodes=nodes))


def diagnose_result(result, effects=None, seed: int = 0, n_folds: int | None = None, workers: int = 1):
    """Diagnose the rank-1 model of an analysis: which physical effect does it miss?

    Runs :func:`rce_gtsam.diagnosis.diagnose.diagnose` on the analysis (:func:`diagnose_inputs`).
    ``effects``: candidate names (``"a,b"`` or a sequence; default every registered effect); ``seed``: seed of the stratified
    edge split; ``n_folds``: cross-validation blocks (default: diagnose's N_FOLDS, 16). Under a preset whose
    settings lie outside the domain the diagnosis is calibrated on (the ``paper`` preset:
    :mod:`rce_gtsam.diagnosis.domain`) it names no effect and its status reads ``"uncalibrated"``. ``workers``:
    processes the candidates are spread over (the same diagnosis; :mod:`rce_gtsam.diagnosis.parallel`).
    Returns a :class:`~rce_gtsam.diagnosis.result.Diagnosis`.
    """
    from .diagnose import diagnose

    return diagnose(**diagnose_inputs(result, effects, seed, n_folds), workers=workers)


def diagnosis_json(diagnosis, result=None) -> dict:
    """The diagnosis JSON object: ``Diagnosis.as_dict()`` plus ``inputs`` and ``frames`` when ``result`` is
    given (the analysis inputs and preset; the video frame of each response column)."""
    data = diagnosis.as_dict()
    if result is not None:
        data["inputs"] = {**{k: str(v) for k, v in result.inputs.items()}, "preset": result.preset.name}
        data["frames"] = [int(f) for f in result.response.frames]
    return data


def diagnosis_for_viz(diagnosis, result=None) -> dict:
    """What :func:`rce_gtsam.viz.write_figures` / ``save_recording`` draw of a diagnosis.

    The JSON object, with ``residuals`` replaced by the (E, T) baseline residual matrix (degrees, NaN =
    missing), ``frames`` (T,) and ``edges`` [(joint, child)] of the rows when ``result`` is given, and
    ``after_prediction`` (E, T): the prediction of the model extended by the verdict effect (None when
    there is no verdict), and ``report``: the text report.
    """
    data = diagnosis_json(diagnosis, result)
    data["residual_summary"] = data.pop("residuals", None)
    data["residuals"] = np.asarray(diagnosis.baseline.residuals, dtype=float)
    if result is not None:
        data["frames"] = np.asarray(result.response.frames)
        data["edges"] = list(result.response.edges)
    else:
        data.pop("edges", None)
        data.pop("frames", None)
    data["after_prediction"] = (np.asarray(diagnosis.verdict_candidate.fit.predict(), dtype=float)
                                if diagnosis.verdict is not None else None)
    data["report"] = diagnosis.report()
    data["residual_analysis_obj"] = getattr(diagnosis, "residual_analysis", None)
    return data


def write_json_atomic(data: dict, path: str | Path) -> Path:
    """Write ``data`` as JSON to a temporary file in the same folder, then rename it onto ``path``."""
    from ..fileio import write_text_atomic
    return write_text_atomic(json.dumps(data, indent=1) + "\n", path)
