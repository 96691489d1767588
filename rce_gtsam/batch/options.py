"""The settings every recording of a batch shares, validated on construction, and the content fingerprint
that decides whether a recording must be recomputed."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

from ..errors import InputError
from ..presets import PRESETS, Preset, with_overrides
from .manifest import Recording

#: Bump when the batch's per-recording outputs change meaning, so old outputs are recomputed.
FINGERPRINT_VERSION = 1
_CHUNK = 1 << 20


@dataclass(frozen=True)
class BatchOptions:
    """What ``rce batch`` applies to every recording.

    preset: preset name for rows with an empty ``preset`` column. overrides: ``--set STAGE.FIELD=VALUE``
    items applied on top of every row's preset. seed: bootstrap and cross-validation seed (None: the
    preset's bootstrap seed, edge-split seed 0 — as ``rce analyze`` / ``rce diagnose``). n_boot: bootstrap
    resamples (None: the preset's). effects: diagnosis candidates (None: every registered effect). figures: write the
    per-recording PNG figures. max_frames: track only the first N frames of a video. model: TAPIR ONNX
    export for video rows (None: the OpenCV tracker).
    """

    preset: str = "default"
    overrides: tuple[str, ...] = ()
    seed: int | None = None
    n_boot: int | None = None
    effects: tuple[str, ...] | None = None
    figures: bool = True
    max_frames: int | None = None
    model: Path | None = None

    def __post_init__(self):
        from ..diagnosis.io import parse_effect_names

        if self.preset not in PRESETS:
            raise InputError("--preset", f"unknown preset {self.preset!r}; choose one of {sorted(PRESETS)}")
        object.__setattr__(self, "overrides", tuple(self.overrides or ()))
        self.preset_for(None)  # a bad --set item fails here, before any work
        object.__setattr__(self, "effects", parse_effect_names(self.effects))
        if self.n_boot is not None and self.n_boot < 0:
            raise InputError("--bootstrap", f"must be >= 0, got {self.n_boot}")
        if self.max_frames is not None and self.max_frames < 1:
            raise InputError("--max-frames", f"must be >= 1, got {self.max_frames}")
        if self.model is not None and not Path(self.model).exists():
            raise InputError("--model", f"not found: {self.model}")

    def preset_for(self, recording: Recording | None) -> Preset:
        """The row's preset (or the batch default) with the ``--set`` overrides."""
        name = (recording.preset if recording is not None else None) or self.preset
        try:
            return with_overrides(name, self.overrides)
        except ValueError as exc:
            raise InputError("--set", str(exc).removeprefix("--set ")) from None


def file_digest(path: Path) -> str:
    """SHA-256 of a file's contents (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def fingerprint(recording: Recording, options: BatchOptions) -> dict:
    """What a recording's outputs depend on: the contents of its input files, the resolved preset and the
    options that change results. ``["hash"]`` is one SHA-256 over all of it; outputs whose stored hash
    equals it are up to date."""
    from .. import __version__

    preset = options.preset_for(recording)
    settings = {"version": FINGERPRINT_VERSION, "rce_gtsam": __version__, "kind": recording.kind,
                "preset": {"name": preset.name, **{k: asdict(getattr(preset, k))
                                                   for k in ("smoother", "bending", "compliance")}},
                "seed": options.seed, "n_boot": options.n_boot,
                "effects": None if options.effects is None else list(options.effects),
                "figures": options.figures}
    if recording.kind == "video":
        settings["max_frames"] = options.max_frames
        settings["model"] = None if options.model is None else _model_digest(Path(options.model))
    files = {name: file_digest(p) for name, p in recording.input_files.items()}
    blob = json.dumps({"settings": settings, "files": files}, sort_keys=True, default=str)
    return {"hash": hashlib.sha256(blob.encode()).hexdigest(), "files": files, "settings": settings}


def _model_digest(model: Path) -> str:
    paths = sorted(model.rglob("*.onnx")) if model.is_dir() else [model]
    return hashlib.sha256("".join(file_digest(p) for p in paths).encode()).hexdigest()
