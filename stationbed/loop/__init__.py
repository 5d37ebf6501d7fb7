"""The closed loop's composition parts (issue 20): named layouts, sensor and
actuator plug-ins, estimators.

Between the model (below) and the executors in ``run/`` (above). Everything here is written
once as casadi expressions; the executors evaluate the same functions (docs/loop.md).
"""

from .actuator import ACTUATORS, Actuator, chain_kinds, get_actuator, pulse_pieces, split_step
from .cmg_cluster import CmgClusterActuator, IdealTorquer, chain_end
from .corruption import Corruption, corrupt_compiled, corrupt_symbolic, draws_layout
from .flight import Flight, flight_columns
from .gyro import RateGyro
from .layout import Layout
from .magnetorquers import Magnetorquers
from .mekf import FILTER, Mekf
from .registry import SENSORS, build_sensors, get_sensor
from .sensor import TRUTH, Sensor, noise_rng
from .star_tracker import StarTracker
from .suite import Suite, SuiteNoise
from .thrusters import ThrusterCluster

__all__ = ["Layout", "Sensor", "TRUTH", "noise_rng", "RateGyro", "StarTracker", "SENSORS", "get_sensor",
           "build_sensors", "Mekf", "FILTER", "Suite", "SuiteNoise", "Flight",
           "flight_columns", "Actuator", "ACTUATORS", "get_actuator", "pulse_pieces", "split_step",
           "ThrusterCluster", "IdealTorquer", "CmgClusterActuator", "chain_end", "Corruption", "draws_layout",
           "corrupt_symbolic", "corrupt_compiled", "Magnetorquers", "chain_kinds"]
