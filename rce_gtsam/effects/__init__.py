"""Physical effect terms for :class:`rce_gtsam.model.ResponseModel`.

Each term is a small class (see :mod:`rce_gtsam.effects.base` for the protocol) with its physics in the
docstring. ``CANDIDATES`` maps the effect names used in reports and JSON to a default instance factory.
"""

from .base import Effect, Parameter
from .delay import Delay
from .dynamics import Dynamics
from .nonlinear import Nonlinear
from .offset import Offset
from .second_mode import SecondMode

#: name -> factory of the default term, in the order the diagnosis tries them.
CANDIDATES = {
    "delay": Delay,
    "dynamics": Dynamics,
    "second_mode": SecondMode,
    "offset": Offset,
    "nonlinear": Nonlinear,
}

EFFECT_NAMES = tuple(CANDIDATES)


def make(name: str) -> Effect:
    """A default instance of the effect called ``name``."""
    try:
        return CANDIDATES[name]()
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; known: {', '.join(CANDIDATES)}") from None


__all__ = ["Effect", "Parameter", "Delay", "Dynamics", "Nonlinear", "Offset", "SecondMode", "CANDIDATES",
           "EFFECT_NAMES", "make"]
