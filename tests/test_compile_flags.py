"""The compiler flags of the generated C (issue 25; stationbed/core/compile.py).

Claims:

* a build with the machine's own instructions (``-march=native``) gives the same bits as a
  portable build of the same C: ``-ffp-contract=off`` keeps the compiler from fusing a multiply
  and an add (the control: without it, on a CPU with FMA, the bits differ - the claim can fail);
* casadi's ``fmax``/``fmin`` built as a comparison (:func:`~stationbed.core.compile.inline_min_max`)
  give libm's value for every pair of numbers, and a NaN in the second argument reaches the
  result (where libm's would hide it);
* a library built for one CPU is never loaded on another: the library's name is keyed by the
  machine (architecture and instruction-set extensions).

Every test points ``STATIONBED_CACHE`` at its own temporary folder.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from stationbed.core import compile as sbc

#: inputs of the bit-for-bit comparisons (enough that an FMA's different rounding shows in one)
N_SAMPLES = 200
#: the flags as shipped (the tests below patch the module's)
SHIPPED, NATIVE = list(sbc.CFLAGS), list(sbc.NATIVE_CFLAGS)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private cache folder, compiling allowed, the once-per-process notices forgotten."""
    d = tmp_path / "cache"
    d.mkdir(mode=0o700)
    monkeypatch.setenv(sbc.CACHE_ENV, str(d))
    monkeypatch.delenv(sbc.NO_COMPILE_ENV, raising=False)
    monkeypatch.setattr(sbc, "_SAID", set(), raising=False)
    if sbc.compiler() is None:
        pytest.skip("no C compiler")
    return d


def _chain() -> ca.Function:
    """40 steps of the logistic map written as multiply-adds (``z <- a z - a z z``, per
    element, a in [3.6, 3.9): chaotic, so one rounding difference grows to a visible one), as
    a ``mapaccum`` loop like the fused chunk: each step is a chance for an FMA's single rounding."""
    z, a = ca.SX.sym("z", 4), ca.SX.sym("a", 4)
    az = a * z
    step = ca.Function("step", [z, a], [ca.fmin(ca.fmax(az - az * z + 1e-3 * ca.sin(a), 0.0), 1.0)])
    acc = step.mapaccum("acc", 40)
    z0, a0 = ca.MX.sym("z0", 4), ca.MX.sym("a0", 4)
    return ca.Function("sb_chain", [z0, a0], [acc(z0, ca.repmat(a0, 1, 40))[:, -1]])


def _values(funcs: dict) -> np.ndarray:
    rng = np.random.default_rng(3)
    f = funcs["sb_chain"]
    return np.array([np.asarray(f(0.1 + 0.8 * rng.random(4), 3.6 + 0.3 * rng.random(4))).ravel() for _ in range(N_SAMPLES)])


def _build_with(monkeypatch, flags: list[str], native: list[str]) -> dict:
    monkeypatch.setattr(sbc, "CFLAGS", flags)
    monkeypatch.setattr(sbc, "NATIVE_CFLAGS", native)
    funcs = sbc.compile_functions([_chain()], "chain")
    assert funcs["__evaluator__"] == sbc.EVALUATOR_C
    return funcs


def _has_fma() -> bool:
    try:
        with open("/proc/cpuinfo") as f:
            return any(ln.startswith("flags") and " fma" in ln for ln in f)
    except OSError:
        return False


def test_native_build_gives_the_portable_builds_bits(cache, monkeypatch):
    portable = _values(_build_with(monkeypatch, SHIPPED, []))
    native = _values(_build_with(monkeypatch, SHIPPED, NATIVE))
    assert np.array_equal(native, portable)


@pytest.mark.skipif(not _has_fma(), reason="the CPU has no fused multiply-add: nothing to contract")
def test_native_build_with_contraction_differs_the_control(cache, monkeypatch):
    """The control of the test above: letting gcc contract (its default) changes the bits, so
    the comparison can see a difference."""
    portable = _values(_build_with(monkeypatch, SHIPPED, []))
    contracted = [f for f in SHIPPED if f != "-ffp-contract=off"] + ["-ffp-contract=fast"]
    native = _values(_build_with(monkeypatch, contracted, NATIVE))
    assert not np.array_equal(native, portable)


def test_the_default_build_gives_casadis_evaluator_bits(cache):
    """The flags in use, against casadi's virtual machine (C++ doubles, no contraction): the
    same operations give the same bits."""
    compiled = _values(sbc.compile_functions([_chain()], "chain"))
    vm = _values({"sb_chain": _chain()})
    assert np.array_equal(compiled, vm)


def _min_max() -> ca.Function:
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    return ca.Function("sb_minmax", [x, y], [ca.vertcat(ca.fmax(x, y), ca.fmin(x, y))])


def test_generated_min_max_is_the_comparison(cache):
    cg = ca.CodeGenerator("m.c", {"with_header": False})
    cg.add(_min_max())
    src = sbc.inline_min_max(cg.dump())
    assert (src.count("stationbed: the comparison"), src.count(sbc._MIN_MAX_GUARD)) == (2, 0)


PAIRS = [(1.0, 2.0), (2.0, 1.0), (-3.5, -3.5), (-1e300, 1e-300), (math.inf, 5.0), (-math.inf, 5.0), (0.0, -2.0)]


@pytest.mark.parametrize("x, y", PAIRS, ids=[f"{x:g},{y:g}" for x, y in PAIRS])
def test_min_max_comparison_gives_libms_value_for_numbers(cache, x, y):
    f = sbc.compile_functions([_min_max()], "minmax")["sb_minmax"]
    assert np.asarray(f(x, y)).ravel().tolist() == [max(x, y), min(x, y)]


def test_nan_in_the_second_argument_reaches_the_result(cache):
    f = sbc.compile_functions([_min_max()], "minmax")["sb_minmax"]
    assert np.all(np.isnan(np.asarray(f(1.0, math.nan))))


def test_a_machine_whose_cpu_flags_are_unknown_builds_portable(monkeypatch):
    monkeypatch.setattr(sbc, "_MACHINE", [(" arm64 arm ", False)])
    assert sbc._native() == []


def test_another_machine_builds_its_own_library(cache, monkeypatch):
    here = sbc.compile_functions([_min_max()], "minmax")["__lib__"]
    monkeypatch.setattr(sbc, "_MACHINE", [(" x86_64 other-cpu sse2", True)])
    there = sbc.compile_functions([_min_max()], "minmax")["__lib__"]
    assert here != there
