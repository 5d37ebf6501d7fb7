"""CMG cluster: momentum models, steering laws, singularity measure (TP-2511 §II.B; Wie 2005).

The cluster stores angular momentum ``h`` (B components) relative to the body. It enters every
formulation through ``H = I ω + Σ I_p ω_p + h`` and puts the torque ``-ḣ - ω × h`` on the body
(``ḣ`` is the body-frame derivative). One module per kind (the scene's ``[cmg] kind``), each a
:class:`~.base.CmgGeometry` registered in :data:`CMG_GEOMETRIES`:

``ideal`` (:mod:`.ideal`)
    a momentum store: state ``h``, input the body-torque command, limits at the control tick.
``dgcmg`` (:mod:`.dgcmg`)
    double-gimbal CMGs: ``s(δ_o, δ_i) = sin δ_i e1 + cos δ_i (cos δ_o e3 - sin δ_o e2)``.
``sgcmg_pyramid`` (:mod:`.pyramid`)
    Wie's four single-gimbal pyramid: ``s_i = cos δ_i s0_i + sin δ_i (g_i × s0_i)``.

For the gimballed kinds ``ḣ = A(δ) δ̇`` with ``A = ∂h/∂δ`` (written analytically); the steering
laws (:mod:`.steering`: ``mp``, ``sr``, ``odsr``) map a requested ``ḣ`` to gimbal rates, which are
rate limited and flagged, never clipped silently. :class:`CmgModel` (:mod:`.cluster`) is the
symbolic model the station builds; :func:`cluster_functions` wraps it as numeric casadi
Functions for tests and controllers.

Adding a geometry: one module here with a :class:`~.base.GimballedGeometry` (or
:class:`~.base.CmgGeometry`) subclass, added to :data:`CMG_GEOMETRIES`, and its row in the
scene's ``CMG_KINDS`` (:mod:`stationbed.scene`: units, gimbals per unit, which keys apply).
"""

from .base import HEAD_PAR, CmgGeometry, GimballedGeometry
from .cluster import CMG_GEOMETRIES, CmgModel, capacity, cluster_functions, cmg_geometry, get_geometry, held_momentum_B
from .dgcmg import DoubleGimbal, dgcmg_triads
from .ideal import IdealCluster
from .pyramid import Pyramid, pyramid_axes
from .steering import DITHER_PHASES, MP_FLOOR, STEERING_LAWS, rate_limit, singularity_measure, steer

__all__ = [
    "CmgModel",
    "CmgGeometry",
    "GimballedGeometry",
    "IdealCluster",
    "DoubleGimbal",
    "Pyramid",
    "CMG_GEOMETRIES",
    "get_geometry",
    "cmg_geometry",
    "HEAD_PAR",
    "dgcmg_triads",
    "pyramid_axes",
    "capacity",
    "held_momentum_B",
    "steer",
    "singularity_measure",
    "rate_limit",
    "STEERING_LAWS",
    "MP_FLOOR",
    "DITHER_PHASES",
    "cluster_functions",
]
