"""Control-design analysis: linear plants of a scene (:mod:`.linearize`), loop margins of a
controller's symbolic form (:mod:`.margins`).

Layer: above ``run`` (it uses the compiled system and the controller registry), below the shipped
controllers (which design on it).
"""

from .linearize import Linearization, OperatingPoint, linearization, linearize, tea_search

__all__ = ["Linearization", "OperatingPoint", "linearization", "linearize", "tea_search"]
