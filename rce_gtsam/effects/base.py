"""The protocol every effect term follows.

The response model (:mod:`rce_gtsam.model`) predicts the bend response y[e, t] (degrees) as

    x_e = L_e z                      operator effects (delay, dynamics): a linear map of the excitation z
    u_e = kappa_e * x_e              the rank-1 core (kappa dimensionless, geometric mean 1)
    y_e = g(u_e) + a_e(t)            an output effect g (nonlinear) and additive effects a (offset, second_mode)

An effect is a small object with configuration in its constructor and no fitted state: the fitted
values live in a ``dict`` (the effect's *state*) that the model passes in and gets back. A state holds
``params`` (static numbers frozen when the model predicts unseen frames: a lag, a frequency, a per-edge
offset) and ``latents`` (per-frame series re-estimated from the data of every new frame, like z itself).

To write a new effect: subclass :class:`Effect`, give it a ``name``, an ``equation``, a ``fitting``
sentence, its ``physics`` and :meth:`Effect.parameters`, implement :meth:`Effect.init` and
:meth:`Effect.update`, and override exactly one of the contribution hooks (``apply``/``apply_T`` for an
operator on z, ``output`` for a pointwise map of kappa*x, ``additive`` for a term added to the prediction).
For the diagnosis, give it :meth:`Effect.evidence` (its residual signature with a null band) and
:meth:`Effect.explain`; then ``rce_gtsam.effects.register(MyEffect)`` makes it a candidate everywhere (the
diagnosis, ``analyze(effects=...)``, the CLI). Where a local search from :meth:`Effect.init` can end in an
optimum that fits the noise, :meth:`Effect.alternative_starts` proposes other starts; the fit that predicts one
row set best from the other's excitation is kept (:mod:`rce_gtsam.model.starts`). The model composes effects by
chaining operators, applying the (single) output map and summing additive terms. ``tests/test_effect_conformance.py`` checks every
registered effect against this protocol.

What an effect may use while it fits is public: the :class:`~rce_gtsam.model.view.FitView` it is handed
(prediction, partial targets, ``index_of(self)`` for its own slot) and the solver steps of
:mod:`rce_gtsam.model.steps` (``sse_after_z`` for a grid start, ``profiled_sse`` to profile z out of a
parameter, ``z_step``). The model never imports this package, so effects depend on the engine and not the
other way round.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..model import FitView


@dataclass(frozen=True)
class Parameter:
    """Description of one (possibly per-edge) static parameter.

    name: key in the state's ``params``; unit: physical unit ("frames", "rad/frame", "deg", "1");
    lower, upper: bounds used by the fit; per_edge: one value per edge (else one shared scalar);
    description: one sentence for the report.
    """

    name: str
    unit: str
    lower: float = -np.inf
    upper: float = np.inf
    per_edge: bool = False
    description: str = ""


class Effect:
    """Base class of a model term (see the module docstring for the protocol)."""

    #: Effect name used in reports and JSON (``delay``, ``dynamics``, ...).
    name: ClassVar[str] = "effect"
    #: The physics as an equation (plain text).
    equation: ClassVar[str] = ""
    #: How the term's parameters are fitted (plain text).
    fitting: ClassVar[str] = ""
    #: Which hook the effect implements: "operator", "output" or "additive".
    kind: ClassVar[str] = "additive"
    #: What a verdict for this effect means physically and what to check (plain text, no API names).
    physics: ClassVar[str] = ""
    #: Where the score test's directions get their excitation z (:mod:`rce_gtsam.diagnosis.score_test`):
    #: "other_rows" (cross-fitted: each node-disjoint row set's directions from the other set's z) or
    #: "own_whitened" (the full fit's z, held fixed, GLS across segments, phase surrogates of the residuals).
    #: "own_whitened" only where effect-free data measured it calibrated: the pipeline's smoother leaves a
    #: signature of its own along some directions (see Dynamics).
    #: "between_rows": no directions; the test asks whether two node-disjoint row sets' residuals share a time
    #: course (an effect with a latent series common to all segments, see SecondMode).
    score_excitation: ClassVar[str] = "other_rows"
    #: The finding a verdict for this effect reports, where the effect is another form of one already in the
    #: library (:class:`~.resonances.Resonances`, each joint's own natural frequency, is a form of "dynamics"):
    #: the diagnosis names the finding and records this form as its ``verdict_effect``. None: its own name.
    finding: ClassVar[str | None] = None
    #: Fewest bend rows (segments) a recording needs before the diagnosis tries this effect (SecondMode needs
    #: two per node-disjoint half to tell a second shared course from the first).
    min_rows: ClassVar[int] = 1
    #: Bounds of a shared parameter that are a physical limit rather than the edge of the form, {name: ("lower"
    #: and/or "upper")}: a fit there is plausible (:mod:`rce_gtsam.diagnosis.plausibility`; e.g. a natural
    #: frequency at its top bound is a quasi-static joint).
    natural_limits: ClassVar[dict] = {}
    #: Named only where its held-out fold t AND its full-data score test are both significant (each at its share
    #: of alpha), instead of either (:func:`~rce_gtsam.diagnosis.decision.is_significant`). For an effect whose
    #: signature the rank-1 model's excitation mostly absorbs, so that its oracle detects nothing and whatever one
    #: test alone finds has been a tracker's artifact (see :class:`~.nonlinear.Nonlinear`). Needs a score test.
    needs_both_tests: ClassVar[bool] = False
    #: True: the diagnosis judges this effect by :meth:`own_family_test` at that test's own level, outside the
    #: Bonferroni family the bend-residual tests share (an effect read from another channel, OutOfPlane's lengths)
    own_family: ClassVar[bool] = False

    @property
    def available(self) -> bool:
        """Whether the term has what it reads (default True): OutOfPlane without the recording's lengths has not,
        and the diagnosis leaves such a term out of its candidates."""
        return True

    @property
    def verdict_name(self) -> str:
        """The name a verdict for this effect reports: its :attr:`finding`, else its own name."""
        return self.finding or self.name

    # -- description ------------------------------------------------------------------------------
    def parameters(self, n_edges: int) -> tuple[Parameter, ...]:
        """Static parameters of this term."""
        return ()

    def latent_names(self) -> tuple[str, ...]:
        """Names of per-frame latent series (length T) in the state's ``latents``."""
        return ()

    def n_free(self, state: dict, n_edges: int, n_frames_observed: int) -> int:
        """Number of fitted degrees of freedom (for AIC/BIC): static parameters + latent frames (fractional
        for shrunk estimates: the sum of their shrinkage factors)."""
        n = sum(n_edges if p.per_edge else 1 for p in self.parameters(n_edges))
        return n + len(self.latent_names()) * n_frames_observed

    # -- fitting ----------------------------------------------------------------------------------
    def init(self, view: "FitView") -> dict:
        """Initial state given the current core fit (``view.kappa``, ``view.z``). The state may carry
        ``"core_start": (kappa, z)``, a better start for the core than the linear fit (taken out of the state
        by the solver)."""
        raise NotImplementedError

    def update(self, state: dict, view: "FitView", frozen: bool) -> dict:
        """One block update of this term's state with everything else held fixed.

        ``frozen=True``: only the latents may change (prediction of new frames with static params fixed),
        and only on ``view.free`` frames. Like :meth:`init`'s, the returned state may carry
        ``"core_start": (kappa, z)``: a better core the effect found (e.g. a global search over each edge's gain
        that the Gauss-Newton steps cannot make); the solver takes it only when it lowers the error.
        """
        return state

    def alternative_starts(self, state: dict) -> list[dict]:
        """Further starting states for a fit that ended at ``state`` (default: none): where a local search can end
        in an optimum that fits the noise, starts that lead to the other optima. The model is then fitted from
        each and the fit that predicts one node-disjoint row set best from the other's excitation is kept
        (:func:`rce_gtsam.model.starts.solve_from_starts`)."""
        return []

    # -- contribution hooks -----------------------------------------------------------------------
    def apply(self, X: np.ndarray, state: dict, view: "FitView") -> np.ndarray:
        """Operator effects: per-edge linear map of X (E, T) (rows = edges)."""
        return X

    def apply_T(self, R: np.ndarray, state: dict, view: "FitView") -> np.ndarray:
        """Operator effects: the transpose (adjoint) of :meth:`apply`, row by row."""
        return R

    def apply_T_sum(self, R: np.ndarray, state: dict, view: "FitView") -> np.ndarray:
        """Operator effects: ``apply_T(R).sum(axis=0)``, (T,), the z step's adjoint when this is the model's only
        operator; override where the sum is cheaper than the rows (:class:`~.dynamics.Dynamics`: one inverse FFT
        instead of one per edge)."""
        return self.apply_T(R, state, view).sum(axis=0)

    def output(self, U: np.ndarray, state: dict, kappa: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Output effects: g(U) and g'(U) elementwise for U = kappa * x (degrees); ``kappa`` (E,) for maps
        that also depend on each edge's gain on its own (a reference pose, :class:`~.nonlinear.Nonlinear`)."""
        return U, np.ones_like(U)

    def rescale_z(self, state: dict, factor: float) -> dict:
        """The state after z is multiplied by ``factor`` and kappa divided by it (the model's normalisation of
        kappa to geometric mean 1): parameters in units of z scale with it (default: none)."""
        return state

    def output_kappa_term(self, dG: np.ndarray, state: dict, kappa: np.ndarray) -> np.ndarray | float:
        """Output effects: d g / d kappa_e minus g'(U) x (what the Gauss-Newton kappa step adds to its
        Jacobian g'(U) x when g depends on kappa also outside U; default 0)."""
        return 0.0

    def additive(self, state: dict, view: "FitView") -> np.ndarray | None:
        """Additive effects: the (E, T) term added to the prediction (degrees)."""
        return None

    def memory_frames(self, state: dict) -> float:
        """How far back in time (frames) the fitted term reaches: a prediction at frame t depends on z up to
        this many frames earlier (0: instantaneous). Cross-validation widens its buffer to cover it."""
        return 0.0

    # -- reporting --------------------------------------------------------------------------------
    def describe(self, state: dict) -> dict:
        """Derived, human-meaningful numbers for the report (default: nothing extra)."""
        return {}

    # -- evidence (used by the diagnosis) -----------------------------------------------------------
    def evidence(self, ctx) -> dict:
        """This effect's signature in the rank-1 baseline's residuals, with its null band (a t statistic or a
        ratio to the noise level): ``ctx`` is a :class:`~rce_gtsam.diagnosis.statistics.ResidualContext`.
        Plain floats and arrays; the diagnosis reports it as the candidate's ``statistics``."""
        return {}

    def score_directions(self, kappa: np.ndarray, z: np.ndarray, s: np.ndarray) -> np.ndarray | None:
        """(J, E, T) the directions in which a *small* amount of this effect moves the rank-1 prediction
        kappa_e z_t (degrees per unit of each direction's parameter): its derivative at the effect's null value,
        for the diagnosis' full-data score test (:mod:`rce_gtsam.diagnosis.score_test`). ``z`` is an excitation
        estimated on other segments (the test's cross-fitting), ``s`` the segments' root distances. None (the
        default): the effect has no fixed signature (per-segment or per-frame parameters) or its test is not
        calibrated, and the held-out test alone judges it. Directions the rank-1 model can absorb (a lag common
        to all segments) are projected out by the test; the conformance test checks that the directions span
        the change of the effect's own prediction near its null value."""
        return None

    def test_directions(self, kappa: np.ndarray, z: np.ndarray, s: np.ndarray):
        """``(G, statistic)`` for the diagnosis' full-data score test, or None (no test): directions G (J, E, T)
        and how their scores combine. ``"quadratic"``: S' V^-1 S, the J directions of J parameters tested at
        once. ``"max"``: the largest standardised score, for J values of one parameter (a scan; the same
        surrogates calibrate the maximum). ``s``: the segments' root distances measured from the excitation's
        clock (where ``z`` is in phase with the segments). Default: :meth:`score_directions`, quadratic."""
        G = self.score_directions(kappa, z, s)
        return None if G is None else (G, "quadratic")

    def heldout_time_basis(self, n_frames: int) -> np.ndarray | None:
        """(K, n_frames) the time courses this effect adds to each segment on its own (per-segment coefficients on
        fixed courses of time: an offset's 1 and a creep's t), or None (the default). Where given, the
        diagnosis names the effect only if, besides the held-out fold t, the held-out gain of per-segment fits on
        these courses beats phase surrogates of the residuals (:mod:`rce_gtsam.diagnosis.heldout_null`), two
        node-disjoint row sets share a time course (the second excitation's test), or the segments' coefficients
        on the courses that change with time are laid out along the branch otherwise than a node's tracking
        error reaches the bends (:mod:`rce_gtsam.diagnosis.drift_pattern`): slow tracker drift gives every
        segment such a course, and the fold t, taking its blocks as independent, would credit it to the
        effect."""
        return None

    def scan_label(self, peak: int) -> dict:
        """For a ``"max"`` test (a scan over one parameter): {name_unit: value} of the scanned value whose score
        was largest (``peak`` indexes the directions of :meth:`test_directions`), kept in ``diagnosis.json`` as
        ``score_peak``. It is where the test saw most, not an estimate of the parameter (the extended fit gives
        that: on a 15-frame synthetic lag the delay's scan peaked at 1.9 frames, whose direction after the
        projection has the least noise). Default: {}."""
        return {}

    def align(self, X: np.ndarray, state: dict, s: np.ndarray) -> np.ndarray | None:
        """(E, T) the rows of X (degrees; NaN = missing) moved onto the excitation's clock by undoing this effect's
        operator at ``state`` (``s``: the rows' root distances), NaN where that is undefined; None (the default):
        the operator cannot be undone exactly. On its clock a model with this effect is the rank-1 model again,
        whose tangent the tests know how to remove: the diagnosis then asks with
        :mod:`rce_gtsam.diagnosis.encompassing` whether a richer candidate explains what this one leaves."""
        return None

    def implausible(self, state: dict, ctx) -> list[str]:
        """Why this fitted state is not plausible physics on the recording (one sentence each; default none).
        ``ctx``: the recording's scales (:class:`~rce_gtsam.diagnosis.plausibility.PlausibilityContext`:
        the largest deflection in deg, the excitation's correlation time in frames). A parameter at a bound of
        its range is checked for every effect already (:func:`~rce_gtsam.diagnosis.plausibility.implausibility`);
        an implausible fit is never named."""
        return []

    @classmethod
    def for_analysis(cls, result) -> "Effect":
        """The term as the diagnosis of an analysis ``result`` (:class:`~rce_gtsam.pipeline.AnalysisResult`) tries
        it: an effect that reads more of the recording than the bend matrix takes its data here (OutOfPlane: the
        segments' lengths). Default: ``cls()``."""
        return cls()

    def own_family_test(self, fit, seed: int = 0) -> dict | None:
        """For an :attr:`own_family` effect: {"p": p-value, "alpha": its level, "heldout_gain_pct": how much the term
        lowers the held-out error on the channel it models (%; optional: without it only p is judged),
        ...statistics} of its own test on the baseline ``fit``, or None (no test: never named). Default None."""
        return None

    def explain(self, summary: dict, statistics: dict) -> str:
        """One or two sentences with the fitted numbers behind a verdict for this effect. ``summary``: the
        extended fit's ``effect_summary()[name]`` (parameters with standard errors plus :meth:`describe`);
        ``statistics``: what :meth:`evidence` returned."""
        return ""

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def __add__(self, other):
        from ..model import ResponseModel
        return ResponseModel() + self + other


def scalar(x) -> float:
    """A 0-d array or number as float."""
    return float(np.asarray(x).reshape(-1)[0])
