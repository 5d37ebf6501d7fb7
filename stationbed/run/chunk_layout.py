"""The held environment's memory, named (issue 20 item 1: layouts own the indices).

The composed loop's vectors are its composition's layouts (loop/compose.py: the carry, the
parameters, the draws, the row); what is left here is the held environment's memory, which the
composed loop's ``env`` block (run/blocks.py: every executor steps it, the per-tick and lockstep
loops through the composed parts) holds.
"""

from __future__ import annotations

from ..core.layout import Layout

__all__ = ["ENV"]

#: the held environment's memory, passed from chunk to chunk (and block to block): the last
#: evaluation ``L_prev`` (3, B components [N m]), its time ``t_prev`` [s], ``have`` (1: there is one)
ENV = Layout(L_prev=3, t_prev=1, have=1)
