"""Is an analysis inside the domain the diagnosis' tests are calibrated on? (the preset's settings)

The diagnosis' full-data tests and held-out scores take two sets of segments that share no tracked node to
carry independent noise, and take what the rank-1 model leaves to be noise plus physics. Their false-alarm
rates were measured on signed bending from the median pose of tracks smoothed node by node (the ``default``
preset). Three settings break those premises, each measured on effect-free simulated recordings (900 frames,
the simulator's default noise; ``python benchmarks/bench_diagnose_domain.py``: the second excitation's test
between the node-disjoint sets, p <= 0.005, against 0 of 40 under ``default`` (2 of 40 at 0.05); with the
surrogates that keep each segment's power on its observed frames, :func:`~rce_gtsam.model.compliance.residual_spectrum`):

* ``smoother.edge_weight > 0``: the edge prior ties each node to its neighbours through the segment between
  them, so a node's tracking error reaches the next set's nodes and the sets share noise (3 of 40; 9 at
  0.05);
* ``bending.rest = "first"``: each segment's deviation is measured from frame 0, whose tracking error then
  stays in that segment as a constant of its own for the whole recording (31 of 40; 33 at 0.05);
* ``compliance.response = "abs"``: |delta beta| folds the sign, a nonlinearity of its own that the effects'
  signatures (a saturation, a second excitation) take up (7 of 40; 18 at 0.05).

The ``paper`` preset sets all three (it reproduces the published method): 32 of 40 (36 at 0.05), and the whole
diagnosis under it named an effect on 9 of the first 10 effect-free recordings and 5 of seeds 10-14 (second excitation,
saturation, dynamics, offset). The paper's other settings, each alone, were not seen to break it: a 5-frame
moving average 0 of 40, its velocity and acceleration weights 0 of 40, an unweighted fit 1 of 40 (1000
surrogates); settings not named here are unmeasured. Outside the domain
the diagnosis still runs (its baseline is the analysis' fit, and the candidates' numbers are there to read),
but names no effect: :func:`settings_outside_domain` says why, and
:attr:`~rce_gtsam.diagnosis.result.Diagnosis.status` reads ``"uncalibrated"``.
"""

from __future__ import annotations

#: (stage, field, test of the value, why the diagnosis' calibration does not hold under such a value)
PREMISES = (
    ("smoother", "edge_weight", lambda v: v > 0,
     "the edge prior ties neighbouring nodes, so segments that share no tracked node share smoothed noise"),
    ("bending", "rest", lambda v: v == "first",
     "deviations from frame 0 keep that frame's tracking error as a constant of each segment's own"),
    ("compliance", "response", lambda v: v == "abs",
     "|delta beta| folds the bending's sign, a nonlinearity the effects' signatures take up"),
)


def settings_outside_domain(preset) -> tuple[str, ...]:
    """The settings of a :class:`~rce_gtsam.presets.Preset` under which the diagnosis is not calibrated, each as
    ``"stage.field=value (why)"``; empty where it is inside the domain (the ``default`` preset)."""
    out = []
    for stage, name, breaks, why in PREMISES:
        value = getattr(getattr(preset, stage), name)
        if breaks(value):
            out.append(f"{stage}.{name}={value} ({why})")
    return tuple(out)
