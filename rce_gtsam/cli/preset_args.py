"""``--preset NAME`` and ``--set STAGE.FIELD=VALUE``: the method configuration of analyze, diagnose and run."""

from __future__ import annotations

import argparse

from ..presets import PRESETS, Preset, with_overrides


def add_preset_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", choices=sorted(PRESETS), default="default",
                   help="method preset: 'paper' reproduces the published pipeline, 'default' is ours")
    p.add_argument("--set", action="append", default=[], metavar="STAGE.FIELD=VALUE", dest="overrides",
                   help="change one setting of the preset (repeatable), e.g. --set compliance.correlated=true "
                        "--set smoother.acceleration_weight=10; stages: smoother, bending, compliance (their "
                        "fields are documented in rce_gtsam/presets.py)")


def add_run_options(p: argparse.ArgumentParser, command: str = "run") -> None:
    """``--seed``, ``--bootstrap`` and ``--candidates`` (the effects the diagnosis tests; ``--effects`` is its
    deprecated old name here) of ``rce run`` and ``rce batch``."""
    from .wording import add_candidates_argument

    p.add_argument("--seed", type=int, default=None,
                   help="seed of every random step of this command: kappa's bootstrap resamples, the motion "
                        "figure's CIs and the diagnosis' cross-validation split (default: the preset's, 0)")
    p.add_argument("--bootstrap", type=int, default=None, metavar="N", help="bootstrap resamples")
    add_candidates_argument(p, command)


def preset_from_args(args: argparse.Namespace) -> Preset:
    """The preset with its ``--set`` overrides; a bad override is an input error (exit 2), raised before any
    work starts."""
    from ..errors import InputError

    try:
        return with_overrides(args.preset, getattr(args, "overrides", None))
    except ValueError as exc:
        raise InputError("--set", str(exc).removeprefix("--set ")) from None
