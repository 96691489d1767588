"""Tracker artifacts: errors a real point tracker makes that look like physics to a test built for white noise.

The simulator's default tracking noise (:class:`~rce_gtsam.sim.simulate.NoiseConfig`) is white-ish,
anisotropic and independent of the motion. Real trackers also make errors that follow the motion. This module
applies such errors to the *true* node positions (px) before the default noise is added; each family is
switched on by name and scaled by one strength multiplier (1 = the size measured by
``benchmarks/measure_artifacts.py`` and stored in ``artifact_presets.json``, which also records where each
number came from). Families (:data:`FAMILIES`):

``speed_error``
    white error whose SD grows with the node's image speed |v| (px/frame), like motion blur:
    SD_along = along_per_speed * |v|, SD_across = across_per_speed * |v| (px).
``lag``
    the tracked point follows the true one through a first-order filter whose time constant grows with speed:
    p[t] = p[t-1] + (x[t] - p[t-1]) / (1 + tau_t), tau_t = tau_frames + tau_per_speed * |v_t| (frames); under
    steady motion the error is -tau v (px).
``gust_occlusion``
    nodes lost in bursts when they move fast (missing not at random): the share of frames a node is missing at
    speed |v| is min(0.9, miss_at_ref * (|v| / ref_speed)^speed_exponent); bursts last burst_frames on average
    (geometric lengths).
``slide``
    the tracked point slides along the stem with the node's own deflection: along error = b_i * d_i(t), d_i the
    node's across-branch displacement from frame 0 (px), b_i ~ N(0, slope_sd) per node (px/px).
``coloured_along``
    along-branch noise correlated in time with power spectrum ~ 1/f^beta (beta 0 = white, 1 = pink,
    2 = random-walk-like), SD sd_px (px) per node.
``drift``
    a slow AR(1) wander that starts at 0 on frame 0 (the tracker starts on the annotation): stationary SD
    along_px / across_px (px), correlation time time_s (s).

Every artifact is 0 on frame 0, where the tracker returns the annotation. Deterministic given the generator
passed in (the simulator spawns it from its seed). Units: px, frames, px/frame, s.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import InputError

#: The artifact families, in the order they are applied.
FAMILIES: tuple[str, ...] = ("lag", "speed_error", "slide", "coloured_along", "drift", "gust_occlusion")

#: The parameters each family reads from a preset, with units.
PARAMETERS: dict[str, dict[str, str]] = {
    "speed_error": {"along_per_speed": "px of along-branch error SD per px/frame of speed",
                    "across_per_speed": "px of across-branch error SD per px/frame of speed"},
    "lag": {"tau_frames": "first-order lag at rest (frames)",
            "tau_per_speed": "extra lag per px/frame of speed (frames per px/frame)"},
    "gust_occlusion": {"miss_at_ref": "share of frames missing at ref_speed (0-1)",
                       "ref_speed": "reference speed (px/frame)",
                       "speed_exponent": "power of speed the missing share grows with",
                       "burst_frames": "mean length of a loss (frames)"},
    "slide": {"slope_sd": "SD over nodes of the along-branch slide per px of across-branch deflection (px/px)"},
    "coloured_along": {"sd_px": "SD of the along-branch coloured noise (px)",
                       "beta": "spectral exponent: power ~ 1/f^beta"},
    "drift": {"along_px": "stationary SD of the along-branch drift (px)",
              "across_px": "stationary SD of the across-branch drift (px)",
              "time_s": "correlation time (s)"},
}

#: The preset file (data): measured strengths with their provenance.
PRESETS_PATH = Path(__file__).with_name("artifact_presets.json")

#: most a node can be missing, whatever its speed
MAX_MISSING = 0.9


@lru_cache(maxsize=4)
def _load_presets(path: str) -> dict:
    return json.loads(Path(path).read_text())


def load_preset(name: str = "measured", path: str | Path | None = None) -> dict[str, dict[str, float]]:
    """The per-family parameters of preset ``name`` from the presets file (``{family: {param: value}}``).

    Raises :class:`InputError` naming the file and the preset or family when it is missing or incomplete.
    """
    p = Path(path) if path is not None else PRESETS_PATH
    try:
        data = _load_presets(str(p))
    except (OSError, ValueError) as err:
        raise InputError(p, f"cannot read the artifact presets: {err}") from None
    presets = data.get("presets", {})
    if name not in presets:
        raise InputError(p, f"no artifact preset {name!r}; known: {', '.join(sorted(presets))}")
    out = {}
    for fam in FAMILIES:
        entry = presets[name].get(fam)
        if not isinstance(entry, dict):
            raise InputError(p, f"preset {name!r} has no entry for family {fam!r}")
        try:
            out[fam] = {k: float(entry[k]) for k in PARAMETERS[fam]}
        except (KeyError, TypeError, ValueError):
            raise InputError(p, f"preset {name!r}, family {fam!r}: needs numbers {', '.join(PARAMETERS[fam])}") from None
    return out


def preset_provenance(name: str = "measured") -> dict:
    """The provenance block of preset ``name`` (command, date, sources per family)."""
    return dict(_load_presets(str(PRESETS_PATH))["presets"][name].get("provenance", {}))


@dataclass(frozen=True)
class ArtifactConfig:
    """Which tracker artifacts to apply and how strongly.

    families: names from :data:`FAMILIES` (empty = none: the simulator's tracks are then exactly those without
        this module). scale: strength multiplier of every family (1 = the preset's measured size; lag's time
        constants, every SD, the slide slope and the missing share are multiplied; beta, the correlation time,
        the burst length and the speed exponent are not). preset: the preset's name in the presets file.
    """

    families: tuple[str, ...] = ()
    scale: float = 1.0
    preset: str = "measured"

    def validate(self) -> None:
        src = "artifact config"
        unknown = [f for f in self.families if f not in FAMILIES]
        if unknown:
            raise InputError(src, f"unknown artifact famil{'y' if len(unknown) == 1 else 'ies'} {unknown}; "
                                  f"known: {', '.join(FAMILIES)}")
        if not (isinstance(self.scale, (int, float)) and math.isfinite(self.scale) and self.scale >= 0):
            raise InputError(src, f"scale must be a finite number >= 0, got {self.scale!r}")
        load_preset(self.preset)

    @property
    def active(self) -> bool:
        return bool(self.families)


@dataclass(frozen=True, eq=False)
class ArtifactResult:
    """Positions with the artifacts applied (N, F, 2) px, visibility (N, F) bool, and the parameters used."""

    xy: np.ndarray
    visible: np.ndarray
    params: dict = field(default_factory=dict)


def branch_tangents(graph, xy: np.ndarray) -> np.ndarray:
    """Unit branch direction (N, F, 2) at each node: sum of unit incoming and outgoing segment directions."""
    row = {nid: i for i, nid in enumerate(graph.nodes)}
    t = np.zeros_like(xy)
    for p, c in graph.edges:
        d = xy[row[c]] - xy[row[p]]
        d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
        t[row[c]] += d
        t[row[p]] += d
    return t / np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-12)


def node_kinematics(graph, true_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(tangent (N, F, 2), normal (N, F, 2), velocity (N, F, 2) px/frame, speed (N, F) px/frame) of the
    true positions; the tangent is the branch direction at each node (:func:`branch_tangents`)."""
    tan = branch_tangents(graph, true_xy)
    nrm = np.stack([-tan[..., 1], tan[..., 0]], axis=-1)
    v = np.gradient(true_xy, axis=1) if true_xy.shape[1] > 1 else np.zeros_like(true_xy)
    return tan, nrm, v, np.linalg.norm(v, axis=-1)


def first_order_lag(x: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """p[t] = p[t-1] + (x[t] - p[t-1]) / (1 + tau[t]), p[0] = x[0]. x (N, F, 2) px, tau (N, F) frames >= 0."""
    p = np.empty_like(x)
    p[:, 0] = x[:, 0]
    w = 1.0 / (1.0 + np.maximum(tau, 0.0))
    for t in range(1, x.shape[1]):
        p[:, t] = p[:, t - 1] + (x[:, t] - p[:, t - 1]) * w[:, t, None]
    return p


def power_law_noise(n: int, F: int, beta: float, rng: np.random.Generator) -> np.ndarray:
    """(n, F) Gaussian series with power spectrum ~ 1/f^beta (f in cycles/frame), each of unit SD. Made by
    shaping white noise in the Fourier domain on twice the length (then cut) so the ends do not wrap."""
    M = 2 * F
    f = np.fft.rfftfreq(M)
    amp = np.zeros_like(f)
    amp[1:] = f[1:] ** (-beta / 2)
    spec = (rng.standard_normal((n, len(f))) + 1j * rng.standard_normal((n, len(f)))) * amp
    x = np.fft.irfft(spec, n=M, axis=1)[:, :F]
    x -= x.mean(axis=1, keepdims=True)
    return x / np.maximum(x.std(axis=1, keepdims=True), 1e-12)


def ar1_from_zero(n: int, F: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """(n, F) AR(1) x[0] = 0, x[t] = rho x[t-1] + sqrt(1 - rho^2) e[t]: unit stationary SD, starting at 0."""
    e = rng.standard_normal((n, F)) * math.sqrt(max(1 - rho ** 2, 0.0))
    x = np.zeros((n, F))
    for t in range(1, F):
        x[:, t] = rho * x[:, t - 1] + e[:, t]
    return x


def occlusion_mask(speed: np.ndarray, miss_at_ref: float, ref_speed: float, exponent: float,
                   burst_frames: float, rng: np.random.Generator) -> np.ndarray:
    """(N, F) bool visibility: a loss starts at frame t with the probability that keeps the node missing a share
    p(|v_t|) = min(MAX_MISSING, miss_at_ref (|v_t| / ref_speed)^exponent) of its frames, bursts geometric with
    mean ``burst_frames``. Frame 0 is always visible."""
    N, F = speed.shape
    p = np.minimum(MAX_MISSING, miss_at_ref * (np.maximum(speed, 0.0) / max(ref_speed, 1e-9)) ** exponent)
    L = max(burst_frames, 1.0)
    start = p / np.maximum(L * (1 - p), 1e-9)  # stationary share p for geometric bursts of mean L
    u = rng.uniform(size=(N, F))
    lengths = rng.geometric(1.0 / L, size=(N, F))
    vis = np.ones((N, F), bool)
    for i in range(N):
        t = 1
        while t < F:
            if u[i, t] < start[i, t]:
                vis[i, t:t + lengths[i, t]] = False
                t += int(lengths[i, t])
            else:
                t += 1
    return vis


def apply_artifacts(graph, true_xy: np.ndarray, fps: float, config: ArtifactConfig,
                    rng: np.random.Generator) -> ArtifactResult:
    """Apply the families of ``config`` to the true positions ``true_xy`` (N, F, 2) px.

    Order: lag (a filter of the true motion), then the additive errors (speed error, slide, coloured along
    noise, drift, each 0 on frame 0), then the occlusion mask. The random draws of every family come from its
    own generator spawned from ``rng``, so switching one family on or off does not change another's draws.
    """
    config.validate()
    N, F, _ = true_xy.shape
    P = load_preset(config.preset)
    k = float(config.scale)
    rngs = dict(zip(FAMILIES, rng.spawn(len(FAMILIES))))
    tan, nrm, v, speed = node_kinematics(graph, true_xy)
    on = set(config.families)
    used: dict[str, dict] = {}
    xy = true_xy.copy()
    if "lag" in on:
        q = P["lag"]
        tau = k * (q["tau_frames"] + q["tau_per_speed"] * speed)
        xy = first_order_lag(true_xy, tau)
        used["lag"] = {**q, "mean_tau_frames": float(tau.mean()), "max_tau_frames": float(tau.max())}
    along = np.zeros((N, F))
    across = np.zeros((N, F))
    if "speed_error" in on:
        q, r = P["speed_error"], rngs["speed_error"]
        along += r.standard_normal((N, F)) * k * q["along_per_speed"] * speed
        across += r.standard_normal((N, F)) * k * q["across_per_speed"] * speed
        used["speed_error"] = dict(q)
    if "slide" in on:
        q, r = P["slide"], rngs["slide"]
        b = r.standard_normal(N) * k * q["slope_sd"]
        d = np.sum((true_xy - true_xy[:, :1]) * nrm, axis=-1)
        along += b[:, None] * d
        used["slide"] = {**q, "slope_per_node": [float(x) for x in b]}
    if "coloured_along" in on:
        q, r = P["coloured_along"], rngs["coloured_along"]
        x = power_law_noise(N, F, q["beta"], r)
        along += k * q["sd_px"] * (x - x[:, :1])
        used["coloured_along"] = dict(q)
    if "drift" in on:
        q, r = P["drift"], rngs["drift"]
        rho = math.exp(-1.0 / max(q["time_s"] * fps, 1e-9))
        along += k * q["along_px"] * ar1_from_zero(N, F, rho, r)
        across += k * q["across_px"] * ar1_from_zero(N, F, rho, r)
        used["drift"] = dict(q)
    along[:, 0] = 0.0
    across[:, 0] = 0.0
    xy = xy + along[..., None] * tan + across[..., None] * nrm
    visible = np.ones((N, F), bool)
    if "gust_occlusion" in on:
        q = P["gust_occlusion"]
        visible = occlusion_mask(speed, k * q["miss_at_ref"], q["ref_speed"], q["speed_exponent"],
                                 q["burst_frames"], rngs["gust_occlusion"])
        used["gust_occlusion"] = {**q, "missing_share": float(1 - visible.mean())}
    return ArtifactResult(xy=xy, visible=visible, params=used)


def parse_families(text: str) -> tuple[str, ...]:
    """``"lag,slide"`` or ``"all"`` (or ``"none"``) as a tuple of families; :class:`InputError` naming
    ``--artifacts`` on an unknown name."""
    out: list[str] = []
    for name in (s.strip() for s in text.split(",")):
        if not name or name == "none":
            continue
        if name == "all":
            out.extend(f for f in FAMILIES if f not in out)
            continue
        if name not in FAMILIES:
            raise InputError("--artifacts", f"unknown artifact family {name!r}; choose from all, {', '.join(FAMILIES)}")
        if name not in out:
            out.append(name)
    return tuple(out)
