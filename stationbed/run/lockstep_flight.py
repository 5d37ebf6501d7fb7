"""The sensing of a lockstep batch (issue 22 item 3): each sample's :class:`~..loop.flight.Flight`
tick (sensors, MEKF), mapped over the samples, one compiled call per tick.

The per-tick loop flies tick k with ``Flight.compiled()`` (``ControlLoop._fly``): the true
measurement, the previous tick's time and rate, the rate integral ``theta_B``, the suite state
and this tick's noise row in; ``theta_B``, the next suite state, what the law sees and the
suite's outputs out. Here the same compiled function is mapped over the samples (casadi
``Function.map``, ``"serial"``: the very machine code once per sample, bit for bit), each sample
with its own parameters (its sensor tables and tuned filter), memory and noise (drawn by its own
loop's ``noise_row``, in tick order, the same blocks).
"""

from __future__ import annotations

import numpy as np

from ..integrators.dop853_batch import mapped

__all__ = ["FlightBatch"]


class FlightBatch:
    """The flight ticks of ``samples`` (their loops fly the same suite structure, ``Flight.key``)."""

    def __init__(self, samples, layout):
        self.loops = [s.loop for s in samples]
        n = self.n = len(self.loops)
        fc = self.fc = mapped(self.loops[0].comp.flight.compiled().f, n, 1)
        a, r = fc.args, fc.res
        self.k, self.t, self.t_prev = a[0], a[1], a[2]
        self.y, self.th, self.om = a[3].reshape(n, -1), a[4].reshape(n, 3), a[5].reshape(n, 3)
        self.xs, self.w = a[6].reshape(n, -1), a[7].reshape(n, -1)
        ps = a[8].reshape(n, -1)
        for i, lo in enumerate(self.loops):
            ps[i] = lo.comp.flight.params
            fm = lo.res.flight  # the sample's flight memory (run/composition.py)
            self.th[i], self.om[i], self.xs[i], self.t_prev[i] = fm.theta_B, fm.omega_prev, fm.xs, fm.t_prev
        self.th1, self.xs1 = r[0].reshape(n, 3), r[1].reshape(n, -1)
        self.seen, self.ys = r[2].reshape(n, -1), r[3].reshape(n, -1)
        self.i_om = layout.slice("omega_BN_B")  # the measurement's (measurement.measurement_fields)

    def fly(self, k: int, t: float, raw: np.ndarray, seen: np.ndarray) -> None:
        """Tick k at time t [s] of every sample from its true measurement ``raw`` (n, n_y):
        writes what each law sees into ``seen``."""
        self.k[:] = k
        self.t[:] = t
        self.y[:] = raw[:, : self.y.shape[1]]
        for i, lo in enumerate(self.loops):
            self.w[i] = lo.noise_row(k)
        self.fc()
        self.th[:] = self.th1
        self.xs[:] = self.xs1
        self.om[:] = raw[:, self.i_om]
        self.t_prev[:] = t
        seen[:, : self.seen.shape[1]] = self.seen

    def to_loop(self, i: int) -> None:
        """Sample i's flight memory and outputs handed back to its run (its rows read ``xs``, ``ys``)."""
        fm = self.loops[i].res.flight
        fm.xs[:], fm.ys[:] = self.xs[i], self.ys[i]
        fm.theta_B[:], fm.omega_prev[:], fm.t_prev = self.th[i], self.om[i], float(self.t_prev[i])
