"""The fused loops' packed vectors, named (issue 20 item 1: layouts own the indices).

A fused chunk (:mod:`.fused`, :mod:`.thrust_fused`) and its many-rows call (:mod:`.fused_rows`)
pass flat vectors between Python and the compiled ``mapaccum``: the carry from tick to tick,
the chunk's parameters, each row's ``info`` (the law's command, the chain end's actuation, the
reference, the law's next state). Each is declared here once, as a
:class:`~stationbed.core.layout.Layout`, and both sides use it: the builder sizes (and packs)
the symbols by it, the executor writes and reads the numbers by its slices. Nobody writes
``par[3 : 3 + ncp]``.
"""

from __future__ import annotations

from ..core.layout import Layout

__all__ = ["chunk_carry", "chunk_par", "chunk_info", "rows_carry", "rows_par", "rows_out", "ENV", "law_carry",
           "flight_carry", "flight_par", "flight_rows_par", "flight_rows_out", "FLIGHT_INFO_IN", "vertcat_by"]

#: the held environment's carry (rates.py, flight_rates.py), passed from chunk to chunk: the last
#: evaluation ``L_prev`` (3, B components [N m]), its time ``t_prev`` [s], ``have`` (1: there is one)
ENV = Layout(L_prev=3, t_prev=1, have=1)


def chunk_carry(nx: int, **tail: int) -> Layout:
    """A chunk's carry: the tick index ``i`` (an exact integer in a double: ``t = t0 + i h``),
    the state ``x`` (the plant's, then the law's own, law_state.py), the ``counts`` of
    rate-limited and saturated ticks, then the executor's ``tail`` (``env``: the held
    environment's carry, rates.py; ``xa``: the thrusters' memory)."""
    return Layout(i=1, x=nx, counts=2, **tail)


def chunk_par(ncp: int, npar: int, **tail: int) -> Layout:
    """A chunk's parameters: the first tick's time ``t0`` [s], the step ``h`` [s], the active
    ticks ``n_act`` (the rest of the chunk is masked), the law's numbers ``cp``, the held
    external torque ``u_ext`` [N m], the model's ``p``, then the ``tail`` (``pa``: the thrusters')."""
    return Layout(t0=1, h=1, n_act=1, cp=ncp, u_ext=3, p=npar, **tail)


def chunk_info(ncmd: int, nact: int, ns: int = 0) -> Layout:
    """One row's ``info``: the law's command ``cmd`` (its command layout's size), the chain
    end's reported values ``act`` (``end.outputs``; none for the ideal torquer), the reference
    ``q_ref`` (scalar first) and the law's next state ``s`` (law_state.py)."""
    return Layout(cmd=ncmd, act=nact, q_ref=4, s=ns)


def rows_carry(nx: int, ne: int) -> Layout:
    """The many-rows call's carry from row to row: the state ``x`` and the held environment's ``env``."""
    return Layout(x=nx, env=ne)


def rows_par(ncp: int, npar: int) -> Layout:
    """The many-rows call's parameters: the step ``h`` [s], ``cp``, ``u_ext`` [N m], ``p``
    (the chunk's parameters after ``t0``, ``h``, ``n_act``, which it sets per row)."""
    return Layout(h=1, cp=ncp, u_ext=3, p=npar)


def rows_out(nx: int, ninfo: int) -> Layout:
    """One row's output of the many-rows call: the row's state ``x``, its ``info``
    (:func:`chunk_info`) and the chunk's ``counts`` of rate-limited and saturated ticks."""
    return Layout(x=nx, info=ninfo, counts=2)


def law_carry(nx: int, ns: int) -> Layout:
    """The carried state: the plant's ``x``, then the law's own ``s`` (law_state.py)."""
    return Layout(x=nx, s=ns)


def flight_carry(nx: int, ns: int, ne: int = 0) -> Layout:
    """The fused flight chunk's carry (fused_flight.py): tick index in the chunk, state, counts
    of rate-limited and saturated ticks, and the flight's memory (previous tick's time and true
    rate, ``theta_B``, the suite state ``xs``); with the environment at its own rate, its held
    carry ``env`` (:data:`ENV`, flight_rates.py)."""
    return Layout(i=1, x=nx, counts=2, t_prev=1, theta_B=3, omega_prev=3, xs=ns, **({"env": ne} if ne else {}))


def flight_par(ncp: int, npar: int, nps: int, **tail: int) -> Layout:
    """The fused flight chunk's parameters: :func:`chunk_par`'s with the chunk's first tick
    ``k0`` after ``n_act`` and the flight's parameters ``ps`` after ``p`` (then the ``tail``:
    ``L_hold``, the held environment torque of a block, flight_rates.py)."""
    return Layout(t0=1, h=1, n_act=1, k0=1, cp=ncp, u_ext=3, p=npar, ps=nps, **tail)


def flight_rows_par(ncp: int, npar: int, nps: int) -> Layout:
    """The flight rows' call's parameters (flight_rows.py): :func:`flight_par`'s after ``t0``,
    ``h``, ``n_act``, ``k0`` (set per row), ``h`` first."""
    return Layout(h=1, cp=ncp, u_ext=3, p=npar, ps=nps)


def flight_rows_out(nx: int, ninfo: int, ns: int, ny: int) -> Layout:
    """One row's output of the flight rows' call: the row's state ``x`` (with the law's), its
    ``info`` (:func:`chunk_info`), the flight's state ``xs`` and outputs ``ys`` after the row's
    tick, the chunk's ``counts``."""
    return Layout(x=nx, info=ninfo, xs=ns, ys=ny, counts=2)


#: the fused flight's ``ffl_info`` inputs, in order (fused_flight.py: the builder's symbols, the
#: executor's arguments by name)
FLIGHT_INFO_IN = ("t", "x", "cp", "u_ext", "p", "k", "t_prev", "theta_B", "omega_prev", "xs", "w", "ps")


def vertcat_by(layout: Layout, **pieces):
    """The casadi column of ``layout`` from each field's ``pieces`` (a list: expressions and
    plain numbers), in the layout's order, in one ``vertcat`` (every field named once). Unlike
    ``Layout.pack`` it keeps the pieces as given (two scalar zeros stay two MX constants, not a
    (2,) one), so a graph written piece by piece generates the same C."""
    import casadi as ca

    if set(pieces) != set(layout.names):
        raise ValueError(f"{layout!r}: pieces for {sorted(pieces)}")
    out = []
    for name in layout.names:
        n = sum(1 if isinstance(v, (int, float)) else v.numel() for v in pieces[name])
        if n != layout.slice(name).stop - layout.slice(name).start:
            raise ValueError(f"layout field {name!r}: {n} numbers, expected {layout.shape(name)}")
        out += pieces[name]
    return ca.vertcat(*out)
