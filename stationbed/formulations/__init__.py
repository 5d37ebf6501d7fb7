"""Equations of motion, one file per form, one registry (DESIGN §7).

``FORMULATIONS`` maps scene names to classes; :func:`get_formulation` also accepts any
:class:`Formulation` subclass.
"""

from __future__ import annotations

from .base import Formulation
from .dalembert import DAlembertForm
from .hamel import HamelForm
from .momentum import MomentumForm
from .momentum27 import Momentum27Form

FORMULATIONS: dict[str, type[Formulation]] = {
    cls.name: cls for cls in (MomentumForm, Momentum27Form, DAlembertForm, HamelForm)
}


def get_formulation(name_or_cls) -> type[Formulation]:
    """The formulation class for a registry name or a :class:`Formulation` subclass.

    Parameters
    ----------
    name_or_cls : str or type  A :data:`FORMULATIONS` name or any :class:`Formulation` subclass.

    Returns
    -------
    type[Formulation]

    Raises
    ------
    ValueError  For an unknown name (the message lists the valid ones).
    """
    if isinstance(name_or_cls, type) and issubclass(name_or_cls, Formulation):
        return name_or_cls
    try:
        return FORMULATIONS[name_or_cls]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown formulation {name_or_cls!r}; valid: {', '.join(sorted(FORMULATIONS))}"
        ) from None


__all__ = ["FORMULATIONS", "Formulation", "get_formulation"]
