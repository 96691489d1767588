"""Physical effect terms for :class:`rce_gtsam.model.ResponseModel`.

Each term is a small class (see :mod:`rce_gtsam.effects.base` for the protocol) with its physics in the
docstring. ``CANDIDATES`` maps the effect names used in reports and JSON to a default instance factory.
"""

from .base import Effect, Parameter
from .delay import Delay
from .dynamics import Dynamics
from .nonlinear import Nonlinear
from .offset import Offset
from .resonances import Resonances
from .second_mode import SecondMode

#: name -> factory of the default term, in the order the diagnosis tries them.
CANDIDATES = {
    "delay": Delay,
    "dynamics": Dynamics,
    "second_mode": SecondMode,
    "offset": Offset,
    "nonlinear": Nonlinear,
    "resonances": Resonances,
}

#: the built-in effects' names (registered effects are added to :data:`CANDIDATES`; see :func:`names`)
EFFECT_NAMES = tuple(CANDIDATES)


def register(cls: type[Effect]) -> type[Effect]:
    """Make an :class:`Effect` subclass a candidate everywhere (diagnosis, ``analyze(effects=...)``, CLI
    names), under its ``name``; returns the class, so it also works as a decorator. A name already
    registered by another class is an error."""
    if not (isinstance(cls, type) and issubclass(cls, Effect)) or not cls.name or cls.name == Effect.name:
        raise ValueError(f"{cls!r} is not an Effect subclass with its own name")
    if CANDIDATES.get(cls.name, cls) is not cls:
        raise ValueError(f"an effect named {cls.name!r} is already registered ({CANDIDATES[cls.name].__name__})")
    CANDIDATES[cls.name] = cls
    return cls


def names() -> tuple[str, ...]:
    """Names of every candidate effect (built-in and registered), in the order the diagnosis tries them."""
    return tuple(CANDIDATES)


def finding(name: str) -> str:
    """What a verdict for the effect called ``name`` reports: its :attr:`~rce_gtsam.effects.Effect.finding` when
    it is another form of a library effect, else ``name`` (unknown names are returned as they are)."""
    return make(name).verdict_name if name in CANDIDATES else name


def make(name: str) -> Effect:
    """A default instance of the effect called ``name``."""
    try:
        return CANDIDATES[name]()
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; known: {', '.join(CANDIDATES)}") from None


# out-of-plane swing reads the segments' lengths besides the bends (its data come with the instance, and it is
# judged by its own test at its own level): registered after the built-ins, so EFFECT_NAMES keeps the bend-only six
from .out_of_plane import OutOfPlane  # noqa: E402
register(OutOfPlane)

__all__ = ["Effect", "OutOfPlane", "Parameter", "Delay", "Dynamics", "Nonlinear", "Offset", "Resonances", "SecondMode", "CANDIDATES",
           "EFFECT_NAMES", "finding", "make", "names", "register"]
