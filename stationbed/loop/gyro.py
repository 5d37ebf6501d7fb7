"""Rate-gyro assembly: the discrete Farrenkopf model (``[[sensor]] kind = "gyro"``).

Continuous model (Farrenkopf 1978; Crassidis & Junkins, *Optimal Estimation of Dynamic
Systems*, 2nd ed., §7.2.1): ``ω̃ = ω + β + η_v``, ``β̇ = η_u``, with white η_v, η_u of spectral
densities σ_v² [rad²/s] and σ_u² [rad²/s³]. A sample reports the rate integrated over its
interval (t_k, t_k+1] of length Δt, ``ω̄ = Δθ/Δt``; exactly in distribution, for any Δt:

``β_k+1 = β_k + σ_u Δt^½ N_u``
``ω̃_k+1 = ω̄ + ½(β_k+1 + β_k) + (σ_v²/Δt + σ_u² Δt/12)^½ N_v``

(the ``Δt/12`` is the variance of the Brownian bridge of β averaged over the interval). Its
Allan variance is ``σ²(τ) = σ_v²/τ + σ_u² τ/3``, the test's truth.

The instrument's errors follow in the order of the hardware: scale factor and misalignment
``(E + M) ω̄`` on the rate, the bias and noise, saturation of each axis at ``±max_rate``, then
quantisation of the integrated angle to ``quantum`` with the remainder carried to the next
sample (a counter: the sum of the output angles stays within half a count of the sum of the
inputs, so quantisation adds no drift).

The state keeps θ at the last sample; the initial state has θ = 0, the truth's ``theta_B`` at
t = 0 (an executor that starts a gyro later sets ``theta_B`` of its state to the truth's then).

What depends on the table alone is a parameter, computed once in :meth:`RateGyro._params`, not
per sample (the same operations in the same order, so the same numbers as the expression gave):
the bias step ``σ_u Δt^½`` and the white-noise level ``(σ_v²/Δt + σ_u² Δt/12)^½``. A gyro
without quantisation (``quantum = 0``, the default) is its own structure (``_structure``),
whose step has no counter: the quantiser's ``floor`` and divisions are computed only by a gyro
that has one (its output is then the same number: the carry stays 0).

Faults (issue 34, ``[[fault]]`` kinds ``gyro_bias_step``, ``gyro_frozen``, ``gyro_dropout``:
:mod:`.sensor_faults`) are numbers of the step, gated by the sample time (exact, fused,
dispersible): a bias step ``b_f`` added to the rate from ``t_bias`` on; the output frozen at its
last value over ``[frozen_on, frozen_off)``; zero (the assembly's packets empty: a dropout)
over ``[dropout_on, dropout_off)``. A sample at t belongs to a window when ``on - Δt/2 <= t <
off - Δt/2`` (samples lie on a grid of Δt: no round-off can move one across an edge). Healthy
(the defaults, :data:`~.sensor_faults.NEVER_S`): ``raw + 0·0`` and the untaken branches, the
same doubles as without them. The last output is kept in the state (``held_B``).
"""

from __future__ import annotations

import math

import casadi as ca

from ..scene import GyroSensor
from .layout import Layout
from .sensor import Sensor
from .sensor_faults import NEVER_S, in_window

__all__ = ["RateGyro"]

#: saturation level used when the table sets none [rad/s] (far beyond any body rate)
NO_SATURATION_RAD_S = 1.0e6


class RateGyro(Sensor):
    """The rate gyro (see the module docstring for the model)."""

    kind = "gyro"
    scene_model = GyroSensor
    #: bias β [rad/s]; θ at the last sample [rad] (to difference the truth's running integral);
    #: the quantiser's carried remainder [rad]
    STATE = Layout(bias_B=3, theta_B=3, carry_B=3, held_B=3)
    #: the sample period, the bias random walk's step ``σ_u Δt^½`` [rad/s] and the white noise's
    #: standard deviation ``(σ_v²/Δt + σ_u² Δt/12)^½`` [rad/s] per sample, E + M's M, the
    #: quantum [rad] (read only by a quantising gyro) and the saturation [rad/s]
    #: (faults, module docstring: the bias step [rad/s] and its start, the windows [s])
    PARAMS = Layout(dt=1, bias_step=1, white=1, M=(3, 3), quantum=1, max_rate=1, fault_bias_B=3, t_bias=1,
                    frozen=2, dropout=2)
    #: the rate integrated over the sample [rad/s], B axes
    OUTPUTS = Layout(omega_B=3)
    reads = ("theta_B",)
    #: N_u (3) then N_v (3)
    n_noise = 6

    def _structure(self) -> tuple:
        return ("quantised",) if self.entry.quantum > 0 else ()

    def _params(self) -> dict:
        e = self.entry
        dt, sv, su = float(e.period), float(e.sigma_v), float(e.sigma_u)
        # the operations (and their order) the step's expression had: the same doubles
        return dict(dt=dt, bias_step=su * math.sqrt(dt), white=math.sqrt(sv * sv / dt + su * su * dt / 12.0), M=e.M,
                    quantum=e.quantum, max_rate=NO_SATURATION_RAD_S if e.max_rate is None else e.max_rate,
                    fault_bias_B=[0.0, 0.0, 0.0], t_bias=NEVER_S, frozen=[NEVER_S, NEVER_S], dropout=[NEVER_S, NEVER_S])

    def _initial(self) -> dict:
        return dict(bias_B=self.entry.bias0, theta_B=[0.0, 0.0, 0.0], carry_B=[0.0, 0.0, 0.0], held_B=[0.0, 0.0, 0.0])

    def _step(self, t, x, truth, w, p):
        dt = p["dt"]
        omega_avg = (truth["theta_B"] - x["theta_B"]) / dt
        bias_next = x["bias_B"] + p["bias_step"] * w[0:3]
        raw = omega_avg + ca.mtimes(p["M"], omega_avg) + 0.5 * (x["bias_B"] + bias_next) + p["white"] * w[3:6]
        raw = raw + (t >= p["t_bias"] - 0.5 * dt) * p["fault_bias_B"]  # a bias step (healthy: + 0 exactly)
        sat = ca.fmin(ca.fmax(raw, -p["max_rate"]), p["max_rate"])
        angle = x["carry_B"] + sat * dt
        if self._structure():  # the counter: whole quanta out, the remainder carried
            q = p["quantum"]
            q_safe = ca.if_else(q > 0, q, 1.0)  # (parameters set to 0 by hand: no counter, no NaN)
            out = ca.if_else(q > 0, q_safe * ca.floor(angle / q_safe + 0.5), angle)
        else:
            out = angle
        rate = out / dt
        rate = ca.if_else(in_window(t, p["dropout"], dt), ca.SX.zeros(3), rate)  # no packet: zeros
        rate = ca.if_else(in_window(t, p["frozen"], dt), x["held_B"], rate)  # the last output again
        return dict(bias_B=bias_next, theta_B=truth["theta_B"], carry_B=angle - out, held_B=rate), dict(omega_B=rate)
