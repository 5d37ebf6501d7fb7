"""The thrusters' columns and summary line (issue 21). In the run they are one actuator of the
chain (run/chain.py ``ActuatorLoop``, the plug-in :class:`~stationbed.loop.thrusters.ThrusterCluster`):
the per-tick loop calls its tick on what the law sees and integrates split at every pulse edge;
the fused loop (:mod:`.composed`) runs the same function inlined as a block.
"""

from __future__ import annotations

from ..loop.thrusters import ThrusterCluster

__all__ = ["thruster_columns", "thruster_parts"]


def thruster_columns(scene) -> list[str]:
    """The CSV columns of the thrusters (:meth:`ThrusterCluster.columns`)."""
    return ThrusterCluster.columns(scene)


def thruster_parts(s: dict) -> list[str]:
    """The run summary line's thruster parts (``stationbed run``), none without thrusters."""
    if "propellant_kg" not in s:
        return []
    per = f" ({s['propellant_kg_per_orbit']:.4g} kg per orbit)" if "propellant_kg_per_orbit" in s else ""
    out = [f"thrusters {s['thruster_firings']} firings, impulse {s['thruster_impulse_Ns']:.4g} N s, propellant "
           f"{s['propellant_kg']:.4g} kg{per}, {s['thruster_control_s']:g} s in thruster-only control"]
    if s.get("thruster_no_torque_about"):
        out.append(f"thrusters make no torque about {s['thruster_no_torque_about']}: a dump or hand-over "
                   "there is not delivered")
    if "thrusters_not_fused" in s:
        out.append(f"thrusters flown per tick: {s['thrusters_not_fused']}")
    return out
