"""The ideal torquer and the CMG cluster as :class:`~.actuator.Actuator` plug-ins (issue 20):
the end of every actuator chain.

* :class:`IdealTorquer` (kind ``ideal_torquer``): what acts without a ``[cmg]`` cluster. One
  channel, on for the whole tick (``on_s = h``), its torque the request (``torque_B = tau_B``),
  nothing left over (``tau_rest_B = 0``). It declares ``FULL_TICK``: there is no edge inside a
  tick, so an executor adds ``torque_B`` to the held external torque ``u_ext`` without splitting
  the step (the same numbers: one piece ``[0, h]``).
* :class:`CmgClusterActuator` (kind ``cmg_cluster``): the plant's CMG cluster. No channel: an
  *internal* actuator (``INTERNAL``) whose command sets the plant's held CMG input (``HELD =
  "u_cmg"``, the field of the model's input layout) through the scene's steering law and the
  rate limit (:meth:`~stationbed.model.cmg.CmgModel.actuate`); it takes all it is given. Being
  part of the plant, it reads the plant's truth (``READS``: the body rate and the cluster's own
  state ``x_cmg``, fields of the formulation's state layout), never what the law sees; its
  ``PARAMS`` are the plant's CMG numbers (the ``cmg`` slice of the model's parameters: a
  dispersed cluster keeps one compiled function). ``out`` = ``(u_cmg, m, rate_limited,
  saturated)``. A law that commands gimbal rates drives it directly:
  :meth:`CmgClusterActuator.rates_function` (no steering, the same limit).

The system (``run/system.py``) builds its compiled ``actuate`` / ``actuate_rates`` (the
cluster's function at the plant's state) from these functions, and every executor composes the
chain's end through ``run.system.chain_end_inputs``: the end block of the composed tick (the
fused loop's, the per-tick loop's parts, its generic path's chain part).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .actuator import Actuator, register_actuator
from .layout import Layout

__all__ = ["IdealTorquer", "CmgClusterActuator", "chain_end"]


@register_actuator
class IdealTorquer(Actuator):
    """The ideal torquer: the law's torque request acts on the body, whole tick, exactly."""

    kind = "ideal_torquer"
    STATE = Layout()
    PARAMS = Layout()
    OUTPUTS = Layout()
    READS = Layout()
    n_channels = 1
    FULL_TICK = True

    def _params(self) -> dict:
        return {}

    def _initial(self) -> dict:
        return {}

    def _command(self, t, h, x, r, tau_B, p):
        return {}, ca.SX.zeros(3), h, tau_B, {}


@register_actuator
class CmgClusterActuator(Actuator):
    """The plant's CMG cluster (``model.cmg``, a :class:`~stationbed.model.cmg.CmgModel`)."""

    kind = "cmg_cluster"
    INTERNAL = True
    HELD = "u_cmg"

    def __init__(self, cluster, pc=None):
        """``cluster``: the model's :class:`~stationbed.model.cmg.CmgModel`; ``pc``: its numbers
        (the plant's ``cmg`` parameter slice), or None (then zeros: the executors pass the
        plant's own)."""
        self.cluster = cluster
        self._pc = pc
        self._fn: dict[str, ca.Function] = {}
        super().__init__()

    def _layouts(self):
        c = self.cluster
        return (Layout(), Layout(pc=c.n_par), Layout(u_cmg=c.nu, m=1, rate_limited=1, saturated=1),
                Layout(omega_BN_B=3, x_cmg=c.nx))

    def _structure(self) -> tuple:
        c = self.cluster
        return (c.geometry.kind, c.steering, c.nx, c.n_par)

    def _params(self) -> dict:
        return {"pc": np.zeros(self.cluster.n_par) if self._pc is None else self._pc}

    def _initial(self) -> dict:
        return {}

    @staticmethod
    def _out(act) -> dict:
        """``CmgModel.actuate``'s ``(u_held, singularity, rate_limited, momentum_saturated)`` by name."""
        u, m, lim, sat = act
        return {"u_cmg": u, "m": m, "rate_limited": lim, "saturated": sat}

    def _command(self, t, h, x, r, tau_B, p):
        act = self.cluster.actuate(t, r["x_cmg"], tau_B, r["omega_BN_B"], p["pc"])
        return {}, ca.SX.zeros(3), ca.SX(0, 1), ca.SX(3, 0), self._out(act)

    def function(self) -> ca.Function:
        """As :meth:`Actuator.function`, built once per instance (its structure is the cluster's)."""
        if "cmd" not in self._fn:
            self._fn["cmd"] = Actuator.function(self)
            Actuator._functions.pop((type(self), self.key), None)  # (kept here, not by key)
        return self._fn["cmd"]

    def rates_function(self) -> ca.Function:
        """The gimbal-rate command path: ``(t, r, rates, p) -> out``, the commanded rates (one
        per gimbal) through the same rate limit and saturation test, no steering."""
        if "rates" not in self._fn:
            c = self.cluster
            ng = c.n_gimbals
            t, r, p = ca.SX.sym("t"), self.reads.symbol("r"), self.param_layout.symbol("p")
            rates = ca.SX.sym("rates", max(ng, 1))
            rr, pp = self.reads.split(r), self.param_layout.split(p)
            act = c.actuate(t, rr["x_cmg"], ca.SX.zeros(3), rr["omega_BN_B"], pp["pc"], direct_rates=rates[0:ng])
            out = self.outputs.pack(self._out(act), symbolic=True)
            self._fn["rates"] = ca.Function(f"{self.key}_rates", [t, r, rates, p], [out], ["t", "r", "rates", "p"],
                                            ["out"], {"cse": True})
        return self._fn["rates"]


def chain_end(model):
    """The actuator that ends the chain of a model: its CMG cluster, else the ideal torquer."""
    return IdealTorquer() if model.cmg is None else CmgClusterActuator(model.cmg)
