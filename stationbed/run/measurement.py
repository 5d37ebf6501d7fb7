"""What a controller sees: the measurement's named layout, and its views (issue 20 item 1).

The measurement vector the compiled ``meas`` function writes (run/system.py) is declared once,
by :func:`measurement_fields` (a :class:`~stationbed.core.layout.Layout`): the system builds it
by name (``Layout.pack``), the executors read it by name (``Layout.slice`` / ``Layout.get``),
and :class:`Measurement` / :class:`BatchMeasurement` are views of it by field. Nobody writes
``y[4:7]``. :func:`measurement_layout` (name -> (offset, size)) stays for code written against
it (a law's ``symbolic`` form); it is the same layout's :meth:`~stationbed.core.layout.Layout.offsets`.

These names are re-exported by :mod:`stationbed.run.controller`, where user code imports them.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import numpy as np

from ..core.layout import Layout

__all__ = ["measurement_fields", "measurement_layout", "command_fields", "Measurement", "BatchMeasurement", "COMMAND_FIELDS"]

#: The law's command by ``Controller.command``: its one field (the size: 3, or the gimbals).
COMMAND_FIELDS = {"torque": "tau_B", "gimbal_rates": "gimbal_rates"}


@lru_cache(maxsize=None)
def measurement_fields(n_gimbals: int, n_app: int) -> Layout:
    """The measurement vector's layout (see :class:`Measurement` for what each field is).

    ``C_ON`` is stored row by row (9 numbers: ``C_ON.ravel()``), as :class:`Measurement`
    reshapes it; ``gimbal`` (n_gimbals) and ``alpha``, ``beta`` (n_app) may be empty.
    """
    return Layout(q_BN=4, omega_BN_B=3, h_B=3, gimbal=n_gimbals, alpha=n_app, beta=n_app, r_N=3, C_ON=9, q_ON=4,
                  omega_ON_O=3, sun_N=3)


def measurement_layout(n_gimbals: int, n_app: int) -> dict[str, tuple[int, int]]:
    """Name -> (offset, size) of the measurement vector (:func:`measurement_fields`'s offsets;
    kept for code written against this form: prefer ``measurement_fields(...).get(y, name)``)."""
    return measurement_fields(n_gimbals, n_app).offsets()


def command_fields(command: str, n_gimbals: int) -> Layout:
    """The law's command layout: ``tau_B`` (3) [N m] or ``gimbal_rates`` (n_gimbals) [rad/s]."""
    return Layout(**{COMMAND_FIELDS[command]: 3 if command == "torque" else n_gimbals})


def _offsets(layout) -> dict[str, tuple[int, int]]:
    """Name -> (offset, size) of a :class:`Layout`, or the older dict itself (as it always was read)."""
    if isinstance(layout, Layout):
        return layout.offsets()
    if isinstance(layout, Mapping):
        return dict(layout)
    raise TypeError(f"measurement layout: a Layout or a name -> (offset, size) dict, got {type(layout).__name__}")


class Measurement:
    """What a controller sees at a tick; every field is a numpy view refreshed in place.

    Attributes
    ----------
    t : float  Time of the tick [s].
    q_BN : (4,)  Attitude quaternion of B relative to N, scalar first.
    omega_BN_B : (3,)  Body rate, B components [rad/s].
    h_B : (3,)  CMG cluster momentum, B components [N m s] (zeros without a cluster).
    gimbal : (n_gimbals,)  Gimbal angles [rad] (dgcmg: outer, inner per unit).
    alpha, beta : (n_arrays,)  Array joint angles [rad].
    r_N : (3,)  Station position, N components [m] (zeros without an orbit).
    C_ON : (3, 3)  DCM from N to LVLH (identity without an orbit).
    q_ON : (4,)  The same as a quaternion, continuous in time (``dcm(q_ON) = C_ON``).
    omega_ON_O : (3,)  Angular velocity of LVLH relative to N, O components [rad/s]
        (``(0, -n, 0)`` on a circular orbit, ``(0, -h/r², 0)`` on a two-body one; zeros without an orbit).
    sun_N : (3,)  Unit vector to the sun, N components (zeros without a [sun] table).

    ``layout``: :func:`measurement_fields`'s (or the older offset dict of :func:`measurement_layout`).
    """

    __slots__ = ("t", "y", "q_BN", "omega_BN_B", "h_B", "gimbal", "alpha", "beta", "r_N", "C_ON", "q_ON", "omega_ON_O", "sun_N")

    def __init__(self, y: np.ndarray, layout):
        self.t = 0.0
        self.y = y
        for name, (o, k) in _offsets(layout).items():
            v = y[o : o + k]
            setattr(self, name, v.reshape(3, 3) if name == "C_ON" else v)


class BatchMeasurement:
    """:class:`Measurement` with a leading sample axis (views of ``y`` (n, n_y), refreshed in
    place: ``q_BN`` (n, 4), ..., ``C_ON`` (n, 3, 3)); ``t`` [s] is every sample's (lockstep)."""

    __slots__ = Measurement.__slots__ + ("n_samples", "layout")

    def __init__(self, y: np.ndarray, layout):
        self.t = 0.0
        self.y = y
        self.layout = layout
        self.n_samples = y.shape[0]
        for name, (o, k) in _offsets(layout).items():
            v = y[:, o : o + k]
            setattr(self, name, v.reshape(-1, 3, 3) if name == "C_ON" else v)
