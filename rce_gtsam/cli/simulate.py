"""``rce simulate --out DIR [--simulator branch|beam] [--effect NAME ...] [--seed N] [--frames N] [--nodes N] [--video]``.

``--simulator beam`` makes the recording with the finite-element beam (:mod:`rce_gtsam.sim.beam`), whose effects
are ``modal``, ``gust_front``, ``two_sources``, ``creep`` and ``stiffening``; its files are the same, and its
truth.json adds ``response_effect_free`` and the diagnosis' name of each effect.

Writes a simulated recording with its ground truth: tracks.csv (noisy, tracker-like), true_tracks.csv
(noise-free), graph.json, truth.json (kappa_true, z_true, response_true, effect parameters), annotations.json
(first-frame node positions) and, with --video, video.mp4 (H.264). ``--realism`` names the camera nuisances
of the video (``rce_gtsam.sim.nuisance.REALISM``: clean = the crisp default render; outdoor = motion blur,
drifting light, a moving soft shadow, ~1 px camera shake, crf 28). ``--artifacts FAMILY[,FAMILY]`` (or ``all``)
adds tracker artifacts to tracks.csv (``rce_gtsam.sim.artifacts``: errors that follow the motion, at the sizes
measured on the project's tracker and the real plants' tracks, times ``--artifact-scale``). ``--effect
out_of_plane`` swings the branch out of its plane (``--oop-share``, ``--tilt-deg``; :mod:`rce_gtsam.sim.three_d`);
``--depth`` adds aligned depth and ``recording.db3`` (:mod:`rce_gtsam.sim.depth`, :mod:`rce_gtsam.sim.recording`).
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace
from pathlib import Path

from ..errors import InputError

# numpy/scipy/pandas come with ..simulate and ..nuisance: they are imported when the command runs or its
# help is printed, not when the parser is built (``rce --help`` and argument errors answer at once)


def _effect_list(values: list[str] | None, simulator: str = "branch") -> tuple[str, ...]:
    EFFECTS = _effect_names(simulator)
    out: list[str] = []
    for v in values or []:
        for name in (s.strip() for s in v.split(",")):
            if not name or name == "none":
                continue
            if name not in EFFECTS:
                raise InputError("--effect", f"unknown effect {name!r} of --simulator {simulator}; choose from "
                                             f"{', '.join(EFFECTS)}")
            if name not in out:
                out.append(name)
    return tuple(out)


def _effect_names(simulator: str) -> tuple[str, ...]:
    """The effect names of a simulator (``branch``: :data:`rce_gtsam.sim.simulate.EFFECTS`; ``beam``:
    :data:`rce_gtsam.sim.beam.BEAM_EFFECTS`)."""
    if simulator == "beam":
        from ..sim.beam import BEAM_EFFECTS
        return BEAM_EFFECTS
    from ..sim.simulate import EFFECTS
    from ..sim.three_d import GEOMETRIC_EFFECTS
    return EFFECTS + GEOMETRIC_EFFECTS


def _strengths(values: list[str] | None, simulator: str = "branch") -> dict[str, float] | None:
    if not values:
        return None
    EFFECTS = _effect_names(simulator)
    out = {}
    for v in values:
        name, sep, num = v.partition("=")
        if not sep or name.strip() not in EFFECTS:
            raise InputError("--strength", f"expected NAME=VALUE with NAME in {', '.join(EFFECTS)}, got {v!r}")
        try:
            out[name.strip()] = float(num)
        except ValueError:
            raise InputError("--strength", f"{v!r}: {num!r} is not a number") from None
    return out


def _forms(values: list[str] | None) -> dict[str, str] | None:
    if not values:
        return None
    from ..sim.simulate import EFFECT_FORMS
    out = {}
    for v in values:
        name, sep, form = (x.strip() for x in v.partition("="))
        if not sep or name not in EFFECT_FORMS or form not in EFFECT_FORMS[name]:
            choices = "; ".join(f"{k}={'|'.join(f)}" for k, f in EFFECT_FORMS.items())
            raise InputError("--form", f"expected NAME=FORM, one of {choices}; got {v!r}")
        out[name] = form
    return out


def _artifacts(text: str | None, scale: float | None):
    """``--artifacts`` / ``--artifact-scale`` as an :class:`~rce_gtsam.sim.artifacts.ArtifactConfig`
    (InputError naming the option on a bad family or scale)."""
    import math

    from ..sim.artifacts import ArtifactConfig, parse_families
    families = parse_families(text) if text is not None else ()
    if text is not None and not families:
        raise InputError("--artifacts", f"names no artifact family ({text!r}); give FAMILY[,FAMILY] or all")
    if scale is not None:
        if not (math.isfinite(scale) and scale >= 0):
            raise InputError("--artifact-scale", f"must be a finite number >= 0, got {scale}")
        if not families:
            raise InputError("--artifact-scale", "is set but no artifact is switched on; add --artifacts FAMILY")
    return ArtifactConfig(families=families, scale=1.0 if scale is None else float(scale))


def _effects_epilog() -> str:
    from ..sim.beam import BEAM_EFFECT_DEFAULTS, BEAM_EFFECT_MEANING, BEAM_EFFECTS
    from ..sim.simulate import EFFECT_DEFAULTS, EFFECT_FORMS, EFFECT_MEANING, EFFECTS
    from ..sim.three_d import GEOMETRIC_EFFECTS
    return ("effects of --simulator branch and the meaning of their strengths: " + "; ".join(
        f"{k} (default {EFFECT_DEFAULTS[k]:g}: {EFFECT_MEANING[k]})" for k in EFFECTS + GEOMETRIC_EFFECTS)
        + ". Forms (--form NAME=FORM): " + "; ".join(
            f"{k}: " + ", ".join(f"{f} ({d})" for f, d in forms.items()) for k, forms in EFFECT_FORMS.items())
        + ". Effects of --simulator beam (a finite-element beam in wind, rce_gtsam.sim.beam): " + "; ".join(
            f"{k} (default {BEAM_EFFECT_DEFAULTS[k]:g}: {BEAM_EFFECT_MEANING[k]})" for k in BEAM_EFFECTS))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate", help="simulate a wind-excited branch with known compliance (and optional hidden effects)",
        description="Simulate a wind-excited branch with known per-edge compliance kappa_true and excitation "
                    "z_true, optional hidden physical effects, tracker-like noisy tracks and, with --video, "
                    "an H.264 rendering. Every random step follows --seed.")

    def format_help() -> str:  # the epilog needs ..simulate: build it only when help is printed
        p.epilog = _effects_epilog()
        return argparse.ArgumentParser.format_help(p)
    p.format_help = format_help
    p.add_argument("--out", type=Path, required=True,
                   help="output folder (created; the files this command writes are replaced, other files are left alone)")
    p.add_argument("--simulator", choices=("branch", "beam"), default="branch",
                   help="branch (default): bends written as kappa_e z_t with effects as laws on it; beam: a finite-"
                        "element cantilever in wind whose effects (modal, gust_front, two_sources, creep, stiffening) "
                        "come from the physics, kappa truth from a static unit load (rce_gtsam.sim.beam)")
    p.add_argument("--effect", action="append", metavar="NAME",
                   help="hidden effect to switch on, repeatable or comma-separated (names below; default: none)")
    p.add_argument("--strength", action="append", metavar="NAME=VALUE",
                   help="override an effect's strength, e.g. --strength delay=10 (units: see below)")
    p.add_argument("--form", action="append", metavar="NAME=FORM",
                   help="an effect's form, e.g. --form delay=quadratic (forms below: the first of each is the default, "
                        "the others are held-out physics the diagnosis does not model exactly)")
    p.add_argument("--seed", type=int, default=0, help="master random seed (default 0)")
    p.add_argument("--frames", type=int, default=900, help="number of video frames (default 900 = 30 s)")
    p.add_argument("--nodes", type=int, default=20, help="number of tracked nodes (default 20)")
    p.add_argument("--layout", choices=("chain", "tree"), default="chain",
                   help="a single chain, or a chain with one side branch")
    p.add_argument("--z-rms", type=float, default=None, metavar="DEG",
                   help="RMS of the wind excitation in degrees per joint (default 1.5)")
    p.add_argument("--clean", action="store_true", help="noise-free tracks (no jitter, drift, jumps or gaps; --artifacts, if given, still apply)")
    p.add_argument("--sigma", action="store_true", help="write a per-observation sigma_px column")
    p.add_argument("--artifacts", default=None, metavar="FAMILY[,FAMILY]",
                   help="tracker artifacts in tracks.csv, comma-separated or 'all': lag, speed_error, gust_occlusion, "
                        "slide, coloured_along, drift (rce_gtsam.sim.artifacts; sizes measured, see "
                        "rce_gtsam/sim/artifact_presets.json)")
    p.add_argument("--artifact-scale", type=float, default=None, metavar="X",
                   help="strength multiplier of the artifacts (default 1 = the measured size)")
    p.add_argument("--video", action="store_true", help="also render video.mp4 (H.264, 640x480)")
    p.add_argument("--oop-share", type=float, default=None, metavar="X",
                   help="with --effect out_of_plane: share of the wind that swings the branch out of its plane "
                        "(its strength, default 0.5; same as --strength out_of_plane=X)")
    p.add_argument("--tilt-deg", type=float, default=None, metavar="DEG",
                   help="tilt of the branch's rest plane about the image x axis, degrees in [-75, 75] (default 30 "
                        "with --effect out_of_plane, else 0: the planar simulator's images)")
    p.add_argument("--depth", action="store_true",
                   help="also render aligned depth (D435i-like errors, rce_gtsam.sim.depth) and write "
                        "recording.db3 (RealSense rgb8 colour + z16 depth, 1.5 MB per frame) beside video.mp4, "
                        "which it implies; truth.json then carries the 3-D truth")
    p.add_argument("--realism", choices=("clean", "outdoor"), default="clean",
                   help="camera nuisances of the video: clean (default; crisp, still, constant light) or outdoor "
                        "(180-degree-shutter motion blur, light drift and a moving soft shadow, ~1 px tripod "
                        "shake, crf 28; true_tracks.csv then includes the camera shake)")
    p.add_argument("--crf", type=int, default=None, metavar="N",
                   help="x264 constant rate factor of the video, 0 (lossless) .. 51 (default: the --realism "
                        "preset's, 16 clean, 28 outdoor): how hard the camera compressed the footage")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..sim.nuisance import REALISM
    from ..sim.simulate import EFFECT_FORMS, NoiseConfig, SimulationConfig, default_form, simulate

    from ..validate import check_output_dir, check_seed

    check_seed(args.seed)
    check_output_dir(args.out)
    effects = _effect_list(args.effect, args.simulator)
    strengths = _strengths(args.strength, args.simulator)
    if args.simulator == "beam":
        for option, given in (("--form", args.form), ("--layout", args.layout != "chain" or None)):
            if given:
                raise InputError(option, "applies to --simulator branch only (the beam is one chain and its effects "
                                         "have one form each)")
    forms = _forms(args.form)
    for option, what, given in (("--strength", "strength", strengths), ("--form", "form", forms)):
        for name in (given or {}):
            if name not in effects:
                raise InputError(option, f"{name}'s {what} is set but the effect is not switched on; add "
                                         f"--effect {name}")
    artifacts = _artifacts(args.artifacts, args.artifact_scale)
    noise = NoiseConfig(enabled=not args.clean, emit_sigma=args.sigma)
    if args.z_rms is not None and not args.z_rms > 0:
        raise InputError("--z-rms", f"must be > 0 degrees, got {args.z_rms}")
    if args.realism != "clean" and not (args.video or args.depth):
        raise InputError("--realism", "only applies to the rendered video: add --video")
    if args.crf is not None and not (args.video or args.depth):
        raise InputError("--crf", "only applies to the rendered video: add --video")
    if args.crf is not None and not 0 <= args.crf <= 51:
        raise InputError("--crf", f"must be an integer in 0..51 (x264's constant rate factor), got {args.crf}")
    render = REALISM[args.realism] if args.crf is None else replace(REALISM[args.realism], crf=args.crf)
    if args.simulator == "beam":
        for option, given in (("--oop-share", args.oop_share), ("--tilt-deg", args.tilt_deg),
                              ("--depth", args.depth or None)):
            if given is not None:
                raise InputError(option, "applies to --simulator branch only")
        return _run_beam(args, effects, strengths, noise, render)
    from .three_d_args import scene_from_args
    strengths, scene = scene_from_args(args, effects, strengths)
    cfg = SimulationConfig(n_nodes=args.nodes, n_frames=args.frames, effects=effects, effect_strength=strengths,
                           effect_form=forms, noise=noise, seed=args.seed, branch_layout=args.layout,
                           artifacts=artifacts, scene3d=scene)
    if args.z_rms is not None:
        cfg = replace(cfg, z_rms_deg=args.z_rms)
    t0 = time.perf_counter()
    sim = simulate(cfg)
    files = sim.write(args.out, video=args.video or args.depth, render=render, depth=args.depth)
    eff = ", ".join(f"{e} (strength {cfg.strength(e):g}"
                    + ("" if e not in EFFECT_FORMS or cfg.form(e) == default_form(e)
                       else f", held-out form {cfg.form(e)}") + ")"
                    for e in cfg.effects) or "none"
    if sim.three_d is not None:
        t3 = sim.three_d
        eff += (f"; 3-D scene: branch plane tilted {t3.tilt_deg:g} deg, root at {t3.root_depth_mm:.0f} mm, "
                f"out-of-plane share {t3.share:g}"
                + (f"; the branch was shrunk to {100 * t3.fit_scale:.0f} % of its planar size to stay in view"
                   if t3.fit_scale < 0.995 else ""))
    obs = sim.tracks.observed
    art = (f"tracker artifacts: {', '.join(artifacts.families)} at {artifacts.scale:g}x the measured size; "
           if artifacts.active else "")
    print(f"simulated {len(sim.graph.nodes)} nodes x {cfg.n_frames} frames (seed {cfg.seed}, {cfg.branch_layout}); "
          f"hidden effects: {eff}; {art}{100 * (1 - obs.mean()):.1f} % of observations occluded "
          f"[{time.perf_counter() - t0:.1f} s]")
    for name, path in files.items():
        print(f"  wrote {path}")
    return 0


def _run_beam(args: argparse.Namespace, effects: tuple[str, ...], strengths: dict | None, noise, render) -> int:
    """``rce simulate --simulator beam``: :func:`rce_gtsam.sim.beam.simulate_beam`, written like the branch's."""
    from ..sim.beam import BeamConfig, simulate_beam

    for name, value in (strengths or {}).items():
        if not (math.isfinite(value) and value > 0):
            raise InputError("--strength", f"{name}={value:g}: a beam effect's strength must be a finite number > 0 "
                                           f"(leave the effect out to switch it off)")
    cfg = BeamConfig(n_nodes=args.nodes, n_frames=args.frames, effects=effects, effect_strength=strengths,
                     noise=noise, seed=args.seed)
    if args.z_rms is not None:
        cfg = replace(cfg, z_rms_deg=args.z_rms)
    cfg.validate()
    t0 = time.perf_counter()
    sim = simulate_beam(cfg)
    files = sim.write(args.out, video=args.video, render=render)
    eff = ", ".join(f"{e} (strength {cfg.strength(e):g})" for e in cfg.effects) or "none"
    f1 = sim.effect_params["_beam"]["f_hz_effect_free"][0]
    obs = sim.tracks.observed
    print(f"simulated a finite-element beam, {len(sim.graph.nodes)} tracked nodes x {cfg.n_frames} frames (seed "
          f"{cfg.seed}; effect-free first mode {f1:.1f} Hz); hidden effects: {eff}; "
          f"{100 * (1 - obs.mean()):.1f} % of observations occluded [{time.perf_counter() - t0:.1f} s]")
    for name, path in files.items():
        print(f"  wrote {path}")
    return 0
