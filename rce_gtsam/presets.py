"""Method presets: configuration as data.

A preset is a :class:`Preset` value made of one frozen config per stage. ``paper`` reproduces the
published reference implementation exactly; ``default`` is our best method. Both run through the
same code path — a preset only changes numbers and switches, never which functions are called.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal


#: The largest factor weight a setting may take (1/px^2): beyond it the smoother's information matrix loses
#: double precision (its condition number grows with the ratio of the weights), and a factor's sigma
#: would be below 1e-4 px.
MAX_WEIGHT = 1e8


def _check(config, rules) -> None:
    """Validate a config on construction: ``rules`` maps field -> (test, requirement text)."""
    for name, (test, need) in rules.items():
        v = getattr(config, name)
        if isinstance(v, float) and not math.isfinite(v) or not test(v):
            raise ValueError(f"{type(config).__name__}.{name} = {v!r}: must be {need}")


def _weight(v) -> bool:
    return 0.0 <= v <= MAX_WEIGHT


@dataclass(frozen=True)
class SmootherConfig:
    """Factor-graph smoother settings.

    Weights multiply squared residuals (cost = w * r^2), i.e. a factor's sigma is 1/sqrt(w) pixels.

    presmooth_window: centred moving-average window in samples (frames) applied first; <= 1 disables.
    measurement_weight: w_m, used when the tracks carry no ``sigma_px`` (then sigma = 1/sqrt(w_m) px).
    velocity_weight, acceleration_weight: w_v, w_a on first / second differences over frames.
    edge_weight: w_e of the edge prior.
    edge_prior: ``"offset"`` pulls each child-minus-parent vector toward its first-frame value (the
        paper's rigid shape prior); ``"length"`` only keeps the segment length near its rest length
        (one GTSAM ``CustomFactor`` per frame), leaving bending free.
    along_across_ratio: measurement sigma along the branch divided by sigma across it (1 = isotropic).
    robust: optional robust loss on the measurement factor (``"huber"`` or ``"cauchy"``), threshold
        ``robust_k`` in whitened units (sigmas).
    marginals: compute marginal covariances (per node-frame and joint per frame).
    window_frames: recordings longer than this are solved in overlapping windows of about this many
        frames (:mod:`rce_gtsam.smoothing.windowing`), so memory stays bounded (GTSAM's graph and Bayes tree take
        ~0.25 MB per frame at 20 nodes, growing as N^2); 0 = always one window (the whole recording).
    window_margin: observed frames of every node solved on each side of a window's core and then
        discarded (burn-in; at most ``window_frames`` frames). The estimate at a frame forgets a
        measurement geometrically in the observed frames between them; with 150 the cores match the
        whole-recording solve to ~1e-9 px (tests/test_long_recordings.py).
    sigma_mode: ``"per_observation"`` solves with each observation's own ``sigma_px``; ``"uniform"`` solves the
        positions with the recording's median observed sigma at every observation, so every node and frame is
        low-passed alike, and scales the covariances back to each observation's own sigma
        (:mod:`rce_gtsam.smoothing.uniform_sigma`; issue #38). Tracks without ``sigma_px`` are unaffected.
    """

    presmooth_window: int = 5
    measurement_weight: float = 1.0
    velocity_weight: float = 0.35
    acceleration_weight: float = 0.2
    edge_weight: float = 0.45
    edge_prior: Literal["offset", "length"] = "offset"
    along_across_ratio: float = 1.0
    robust: Literal["huber", "cauchy"] | None = None
    robust_k: float = 1.345
    marginals: bool = True
    window_frames: int = 1200
    window_margin: int = 150
    sigma_mode: Literal["per_observation", "uniform"] = "per_observation"

    def __post_init__(self):
        _check(self, {
            "presmooth_window": (lambda v: v >= 0, ">= 0 frames (<= 1 disables the moving average)"),
            "measurement_weight": (lambda v: 0 < v <= MAX_WEIGHT, f"> 0 and <= {MAX_WEIGHT:g} (1/px^2)"),
            "velocity_weight": (_weight, f"between 0 and {MAX_WEIGHT:g} (1/px^2)"),
            "acceleration_weight": (_weight, f"between 0 and {MAX_WEIGHT:g} (1/px^2)"),
            "edge_weight": (_weight, f"between 0 and {MAX_WEIGHT:g} (1/px^2)"),
            "along_across_ratio": (lambda v: 1e-3 <= v <= 1e3, "between 1e-3 and 1e3"),
            "robust_k": (lambda v: v > 0, "> 0 (sigmas)"),
        })
        if self.sigma_mode not in ("per_observation", "uniform"):
            raise ValueError(f"smoother.sigma_mode must be one of ['per_observation', 'uniform'], "
                             f"got {self.sigma_mode!r}")


@dataclass(frozen=True)
class BendingConfig:
    """Bending-angle settings.

    signed: True = signed turning angle via atan2 (degrees, 0 = straight); False = the paper's unsigned
        interior angle arccos in [0, 180] degrees.
    rest: ``"first"`` = rest angle at the first common frame (paper); ``"median"`` = median over inlier
        frames (robust to a deflected or noisy first frame); ``"common_median"`` = median over the frames where
        every bend is observed (:func:`~rce_gtsam.bending.angles.common_frames`; each bend's own median when
        there are too few): with nodes lost in gusts, each bend's own median sits at a different excitation and
        biases kappa (issue #38).
    mad_threshold: modified z-score cut-off (0.6745 |d - med| / MAD) for the outlier mask.
    """

    signed: bool = False
    rest: Literal["first", "median", "common_median"] = "first"
    mad_threshold: float = 3.5

    def __post_init__(self):
        _check(self, {"mad_threshold": (lambda v: v >= 0, ">= 0 (a modified z-score)")})
        if self.rest not in ("first", "median", "common_median"):
            raise ValueError(f"bending.rest must be one of ['first', 'median', 'common_median'], got {self.rest!r}")


@dataclass(frozen=True)
class ComplianceConfig:
    """Rank-1 compliance fit settings.

    response: ``"abs"`` fits |delta| (paper, z >= 0); ``"signed"`` fits signed delta with a signed z.
    shrinkage: how far log kappa_hat is pulled toward 0 (kappa = 1): ``"count"`` (paper) uses
        s = n / (n + prior_strength) with n the usable frames; ``"precision"`` uses the estimate's own
        precision, s = tau^2 / (tau^2 + se^2(log kappa_hat)) with tau = ``prior_sd_log`` and se from the
        residual variance and an autocorrelation-corrected sample size (a log-normal prior on kappa), so
        only edges whose response is buried in noise move toward 1.
    prior_strength: lambda of the count-based shrinkage kappa = kappa_hat ** (n / (n + lambda)).
    prior_sd_log: tau, the prior standard deviation of log kappa for ``"precision"`` shrinkage (1.0: 95 %
        of segments within a factor e^2 ~ 7 of the branch's geometric mean).
    n_iter, tol: ALS iteration cap and stop tolerance on max |log kappa change|.
    weighted: weight each entry by 1 / (propagated angle variance) instead of equally.
    correlated: use the whole propagated covariance between the bends of a frame
        (generalised least squares, :func:`~rce_gtsam.model.compliance.fit_rank1_gls_batch`): neighbouring
        bends share a node, so one node's tracking error turns them in opposite directions and their
        angle errors are strongly negatively correlated. Replaces ``weighted``'s variances (its diagonal).
        Needs the signed response.
    bootstrap: how resampled data sets are made. ``"block"`` (paper): moving blocks of ``block_length``
        frames of the data. ``"phase"``: the fitted model kappa_hat z_hat plus phase-randomised residuals
        (multivariate Fourier surrogates: every residual row keeps its spectrum, every pair of rows its
        cross-spectrum; see :func:`~rce_gtsam.model.surrogates.phase_randomised_residuals`). Slow tracker
        drift (correlated over seconds) enters kappa's error but is longer than any usable block. The
        intervals are then widened for the few independent samples the error rests on
        (:func:`~rce_gtsam.model.uncertainty.small_sample_factor`). Needs the signed response. The effects
        fit (``rce analyze --effects``) always resamples blocks.
    n_boot, block_length: bootstrap resamples and block length (frames); seed: RNG seed.
    time_split_blocks: K > 1 widens the intervals by how much kappa varies between K disjoint blocks of
        frames beyond what they allow (batch means, :mod:`rce_gtsam.model.time_split`); 0 = off (paper).
    posterior_floor: with ``"precision"`` shrinkage and the phase bootstrap, no interval is narrower than the
        posterior of the prior the shrinkage used: each side at least 1.96 tau sqrt(1 - s) (times the small-sample
        factor) from kappa in log, s the edge's shrinkage (:func:`~rce_gtsam.model.uncertainty.posterior_floor`).
        Where the data hardly determine kappa (s well below 1) the interval then says so. False = off (paper).
    """

    response: Literal["abs", "signed"] = "abs"
    shrinkage: Literal["count", "precision"] = "count"
    prior_strength: float = 12.0
    prior_sd_log: float = 1.0
    n_iter: int = 60
    tol: float = 1e-4
    weighted: bool = False
    correlated: bool = False
    n_boot: int = 250
    block_length: int = 25
    bootstrap: Literal["block", "phase"] = "block"
    seed: int = 0
    time_split_blocks: int = 0
    posterior_floor: bool = False

    def __post_init__(self):
        _check(self, {
            "prior_strength": (lambda v: v >= 0, ">= 0 (frames)"),
            "prior_sd_log": (lambda v: v > 0, "> 0"),
            "n_iter": (lambda v: v >= 1, ">= 1"),
            "tol": (lambda v: v > 0, "> 0"),
            "n_boot": (lambda v: v >= 0, ">= 0 (0 disables the bootstrap)"),
            "block_length": (lambda v: v >= 1, ">= 1 frame"),
            "seed": (lambda v: 0 <= v < 2**63, "between 0 and 2**63 - 1"),
            "time_split_blocks": (lambda v: v == 0 or v >= 2, "0 (off) or >= 2 blocks"),
        })
        choices = {"response": ("abs", "signed"), "shrinkage": ("count", "precision"), "bootstrap": ("block", "phase")}
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"compliance.{name} must be one of {list(allowed)}, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class Preset:
    name: str
    smoother: SmootherConfig = field(default_factory=SmootherConfig)
    bending: BendingConfig = field(default_factory=BendingConfig)
    compliance: ComplianceConfig = field(default_factory=ComplianceConfig)

    def with_(self, **stage_overrides) -> "Preset":
        """Copy with per-stage field overrides, e.g. ``preset.with_(compliance={"n_boot": 50})``."""
        changes = {}
        for stage, fields in stage_overrides.items():
            changes[stage] = replace(getattr(self, stage), **fields)
        return replace(self, **changes)


PAPER = Preset(name="paper")

#: Our method. Each choice was measured against simulated ground truth (benchmarks/bench_presets.py;
#: effect-free branches, 900 frames, 5 seeds, median kappa log-RMSE; paper preset 0.774):
#: * no edge prior: the paper's frame-0 offset prior pulls every frame toward the first frame's shape
#:   and scrambles kappa (all other choices below with the offset prior: 0.870). A length-only prior
#:   did not improve kappa (8 seeds: 0.343 vs 0.331 without) and makes the problem
#:   non-convex: LM needs 7-25 iterations (11 s on plant 2) and can stop short at tracking glitches.
#:   Without it the graph is linear and LM converges in one iteration. It stays available
#:   (``edge_prior="length"``, ``edge_weight > 0``);
#: * a stronger acceleration prior instead of the 5-frame moving average: tracker noise is white-ish
#:   (lag-1 autocorrelation ~0.26) while wind sway is slow, so a low-pass helps. With w_a / w_m = 20 the
#:   smoother's cut-off period is ~12 frames (~2.5 Hz at 30 fps), above the sway modes of a branch;
#:   weights 5..50 gave the same kappa error;
#: * signed turning angles, a median rest pose and a signed excitation (no |delta| noise floor);
#: * precision-based shrinkage (a log-normal prior, tau = 1): an edge whose bending is buried in noise
#:   no longer collapses to kappa ~ 0 and drags every other kappa through the geometric-mean
#:   normalisation (10 seeds: median log-RMSE 0.331 -> 0.226; worst seed 1.12 -> 0.24);
#: * a marginal-variance-weighted fit (each angle weighted by 1 / its propagated variance): neutral on
#:   simulated tracks (20 seeds: 0.169 -> 0.166) but it keeps long occlusions, where the smoother can only
#:   interpolate, from posing as bending. Through the OpenCV tracker on rendered simulator videos it raised
#:   Spearman(kappa, kappa_true) 0.812 -> 0.934, 0.678 -> 0.816, 0.864 -> 0.903, 0.655 -> 0.653 (seeds 0,
#:   1 (400 frames), 2, 3);
#: * phase-randomised residual bootstrap with a small-sample widening instead of moving blocks: the
#:   excitation's power sits in a few of the lowest frequencies (an effective 2.1 / 4.0 independent
#:   samples on plants 2 / 1), where slow tracker drift lives too, so blocks of frames miss most of
#:   kappa's error. 95 % intervals covered kappa_true for 82.8 % of edges with blocks, 91.1 % with this
#:   (20 seeds of simulated tracks with 2-s drift). Median U_e on plant 1 / 2: 0.84 / 0.88 with
#:   blocks, 1.17 / 1.22 with this (1.20 / 1.21 since the surrogates keep each segment's power on its
#:   observed frames, and 92.5 % coverage);
#: * the posterior floor (``posterior_floor``): no interval narrower than the posterior the precision shrinkage
#:   implies. Truth in the 95 % interval on the texture bed with our tracker's tracks 66 -> 84 % (record
#:   ``texture_bed``, the bed before its correction; 86 % on the corrected one), with white 0.36 px node noise there
#:   72 -> 92 %; on the simulator's effect-free tracks (900 frames) 93 -> 97 % (seeds 0-19) and 97.5 % (seeds
#:   100-119), median interval width x1.81 -> x2.49. On the real plants (TAPIR tracks) median U_e 1.20 / 1.21 -> 3.29
#:   / 2.74, and kappa from disjoint thirds of the frames scatters as the intervals allow on plant 1
#:   (``benchmarks/bench_ci_thirds.py``: SD(z) 1.68 -> 1.41 against 1.39 for surrogates that obey the model exactly),
#:   still more than that on plant 2 (2.20 -> 1.93, null 1.46);
#: * kept OFF because they did not help: the anisotropic measurement covariance (0.385) and the Huber
#:   loss (0.278); both stay available as settings.
#: * kept OFF, a trade: the correlated (generalised least squares) fit, ``correlated=True``. It uses
#:   the -0.63 error correlation between neighbouring bends (plants 1 and 2 alike). Under white node
#:   noise it cuts kappa's error 3x (tests/test_gls.py: 0.07 vs 0.21). On simulated tracks, which
#:   also drift, the gain is smaller:
#:   - median log-RMSE 0.148 vs 0.166 (seeds 0-19) and 0.180 vs 0.194 (seeds 100-119); better on
#:     12 and 13 of 20 seeds;
#:   - but its phase-bootstrap intervals are 22 % narrower and cover kappa_true for only 84.7 % /
#:     83.1 % of edges (default: 91.1 % / 86.4 %);
#:   - on the real plants, kappa from separate thirds and quarters of the video agreed better on
#:     plant 1 (spread 0.296 / 0.363 vs 0.319 / 0.434) and worse on plant 2 (0.378 / 0.370 vs
#:     0.377 / 0.322). Not proven better;
#:   - its bootstrap costs ~14x the CPU (plant 2: 6.9 vs 0.5 s).
#: * kept OFF, measured: one measurement sigma in the smoother's solve (``sigma_mode="uniform"``, issue #38). On the
#:   user's path (our tracker on 40 effect-free renders) it named an effect on 3 of 40 (7.5 %: offset 2, dynamics 1)
#:   where each observation's own sigma names 2 of 40, so the default keeps ``per_observation``. What it fixes
#:   (each observation's sigma is kept in the covariances): with each observation's own sigma in the solve, the
#:   nodes and fast frames the tracker is less sure of are low-passed harder, which kappa reads as compliance.
#:   Texture bed, TRUE positions with the tracker's visibility and sigmas (10 cases; measured with a calibrated
#:   tracker sigma that was later reverted): log-RMSE 0.157 -> 0.033, truth in the 95 % CI 66 -> 80 %; our tracks there 0.826 ->
#:   0.835 (64 -> 67 %); simulated tracks (20 seeds) 0.249 -> 0.250 (94 %), with gust losses 0.362 -> 0.335 (1x),
#:   0.491 -> 0.474 (2x); plant 2, our tracks against the TAPIR run's kappa: log-RMS 0.41 -> 0.42, inside its CI
#:   16 -> 15 of 23. Tracks without sigma (TAPIR's CSVs, the paper preset) are unchanged
#:   (record ``gap_bias``);
#: * kept OFF, not proven: ``bending.rest="common_median"``. It takes the rest over the frames all bends share, so
#:   nodes lost in gusts no longer offset each bend's rest differently: true positions on the bed 97 % in CI
#:   (80 % without), effect-free simulated true positions 88 % (81 %); but true positions with one sigma on the bed
#:   66 % (76 %), and on the plants' TAPIR tracks it moves kappa by a log-RMS of 0.08-0.09 with no truth to say
#:   which is right.
DEFAULT = Preset(
    name="default",
    smoother=SmootherConfig(presmooth_window=1, velocity_weight=0.0, acceleration_weight=20.0,
                            edge_weight=0.0),
    bending=BendingConfig(signed=True, rest="median"),
    compliance=ComplianceConfig(response="signed", shrinkage="precision", weighted=True, bootstrap="phase",
                                posterior_floor=True),
)

PRESETS: dict[str, Preset] = {p.name: p for p in (PAPER, DEFAULT)}


def get_preset(name: str | Preset) -> Preset:
    """Look up a preset by name (or pass a :class:`Preset` through)."""
    if isinstance(name, Preset):
        return name
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}") from None


_STAGES = ("smoother", "bending", "compliance")


def _parse_value(text: str, annotation: str, where: str):
    """``text`` as the type a config field is annotated with (annotations are strings here)."""
    t = text.strip()
    kind = annotation.replace(" ", "")
    if kind.startswith("Literal["):
        choices = [c.strip("'\"") for c in kind[len("Literal["):].split("]")[0].split(",")]
        optional = kind.endswith("|None")
        if optional and t.lower() in ("none", "null", ""):
            return None
        if t not in choices:
            raise ValueError(f"{where}: {t!r} is not one of {choices + (['none'] if optional else [])}")
        return t
    if kind == "bool":
        if t.lower() in ("1", "true", "yes", "on"):
            return True
        if t.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"{where}: {t!r} is not a boolean (true/false)")
    try:
        if kind == "int":
            return int(t)
        if kind == "float":
            return float(t)
    except ValueError:
        raise ValueError(f"{where}: {t!r} is not a{'n integer' if kind == 'int' else ' number'}") from None
    raise ValueError(f"{where}: fields of type {annotation} cannot be set from text")


def parse_overrides(items) -> dict[str, dict]:
    """``["compliance.correlated=true", "smoother.acceleration_weight=10"]`` -> per-stage field overrides
    for :meth:`Preset.with_`. Each value is parsed as its field's type; an unknown stage or field, or a
    value of the wrong type, raises ValueError naming the item and what is allowed."""
    from dataclasses import fields

    out: dict[str, dict] = {}
    for item in items or ():
        key, sep, value = str(item).partition("=")
        stage, dot, name = key.strip().partition(".")
        if not sep or not dot:
            raise ValueError(f"--set {item!r}: expected STAGE.FIELD=VALUE, e.g. compliance.n_boot=500")
        if stage not in _STAGES:
            raise ValueError(f"--set {item!r}: unknown stage {stage!r}; stages are {list(_STAGES)}")
        known = {f.name: f for f in fields(getattr(Preset(name="_"), stage))}
        if name not in known:
            raise ValueError(f"--set {item!r}: {stage} has no field {name!r}; its fields are {sorted(known)}")
        out.setdefault(stage, {})[name] = _parse_value(value, str(known[name].type), f"--set {item!r}")
    return out


def with_overrides(preset: str | Preset, items) -> Preset:
    """``preset`` with ``--set`` style overrides applied (see :func:`parse_overrides`); its name records
    them, e.g. ``default[compliance.correlated=True]``."""
    base = get_preset(preset)
    overrides = parse_overrides(items)
    if not overrides:
        return base
    tag = ",".join(f"{s}.{k}={v}" for s, kv in overrides.items() for k, v in kv.items())
    return replace(base.with_(**overrides), name=f"{base.name}[{tag}]")
