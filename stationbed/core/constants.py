"""Physical constants, each with its unit in the name and its source (one module for the project)."""

from __future__ import annotations

__all__ = ["MU_EARTH_M3_S2", "R_EARTH_M"]

#: Earth's gravitational parameter [m³/s²] (IERS 2010 / WGS-84 GM)
MU_EARTH_M3_S2 = 3.986004418e14
#: Earth's equatorial radius [m] (WGS-84)
R_EARTH_M = 6378137.0
