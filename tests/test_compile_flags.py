"""The compiler flags of the generated C (issue 25; stationbed/core/compile.py).

Claims:

* a build with the machine's own instructions (``-march=native``) gives the same bits as a
  portable build of the same C: ``-ffp-contract=off`` keeps the compiler from fusing a multiply
  and an add (the control: without it, on a CPU with FMA, the bits differ - the claim can fail);
* casadi's ``fmax``/``fmin`` built as a comparison (:func:`~stationbed.core.compile.inline_min_max`)
  give libm's value for every pair of numbers, and a NaN in the second argument reaches the
  result (where libm's would hide it);
* a library built for one CPU is never loaded on another: the library's name is keyed by the
  machine (architecture and instruction-set extensions);
* products added and subtracted in turn (a quaternion product, as the MEKF and the kinematics
  write it) give casadi's evaluator's bits: ``-fno-tree-slp-vectorize`` keeps gcc 12 from
  fusing them into ``vfmaddsub`` on an AVX-512 CPU, which ``-ffp-contract=off`` does not (the
  control: without the flag, where the compiler fuses, the bits differ);
* end to end: the fused loop flown on gyros, star trackers and the MEKF (the estimated scene,
  every kind of compiled function the loop has) gives, compiled, the bits casadi's evaluator
  gives for the same expressions (``STATIONBED_NO_COMPILE``, in a subprocess);
* each generated function tests an input for null once (:func:`~stationbed.core.compile.hoist_inputs`),
  not at every read, and a null (empty) input still reads as zeros.

Every test points ``STATIONBED_CACHE`` at its own temporary folder, except the two whole-loop
checks, which use the run's cache on purpose (the fused loops' libraries the suite builds anyway).
"""

from __future__ import annotations

import json
import math
import os
import platform
import re
import shutil
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from stationbed.core import compile as sbc

ROOT = Path(__file__).resolve().parents[1]
#: the end-to-end comparison's run [s]: rows at 0, 10 and 20 s, the star trackers' 20 samples
#: and their filter updates among the 200 ticks
LOOP_S = 20.0
#: a bound on each subprocess of the end-to-end comparison [s] (~5 s each when the library is cached)
LOOP_TIMEOUT_S = 600
#: x86 fused multiply-add mnemonics (vfmadd…, vfmsub…, vfnmadd…, vfmaddsub…, vfmsubadd…)
FMA_MNEMONIC = re.compile(r"\svf(n)?m(add|sub)[a-z0-9]*\s")

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


def _cpu_has(flag: str) -> bool:
    """Whether the CPU's ``flags`` line in /proc/cpuinfo lists ``flag`` (False where unreadable)."""
    try:
        with open("/proc/cpuinfo") as f:
            return any(ln.startswith("flags") and f" {flag}" in ln for ln in f)
    except OSError:
        return False


def _has_fma() -> bool:
    return _cpu_has("fma")


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


# -- products added and subtracted in turn: no fused multiply-add from the vectoriser -------
def _quaternion_chain() -> ca.Function:
    """40 quaternion products ``q <- (q ⊗ r)·(1 + 1e-7)`` (each component a sum of four products
    with signs alternating: the pattern gcc's straight-line vectoriser fuses), as a ``mapaccum``."""
    from stationbed.core.rotation import quat_mult

    q, r = ca.SX.sym("q", 4), ca.SX.sym("r", 4)
    step = ca.Function("qstep", [q, r], [quat_mult(q, r) * 1.0000001])
    acc = step.mapaccum("acc", 40)
    q0, r0 = ca.MX.sym("q0", 4), ca.MX.sym("r0", 4)
    return ca.Function("sb_qchain", [q0, r0], [acc(q0, ca.repmat(r0, 1, 40))[:, -1]])


def _quaternion_values(f) -> np.ndarray:
    rng = np.random.default_rng(3)
    return np.array([np.asarray(f(rng.standard_normal(4), 0.5 * rng.standard_normal(4))).ravel()
                     for _ in range(N_SAMPLES)])


def test_quaternion_products_give_casadis_evaluator_bits(cache):
    compiled = _quaternion_values(sbc.compile_functions([_quaternion_chain()], "qchain")["sb_qchain"])
    assert np.array_equal(compiled, _quaternion_values(_quaternion_chain()))


def _avx512() -> bool:
    return _cpu_has("avx512f")


def _gcc_major() -> int | None:
    cc = sbc.compiler()
    if cc is None:
        return None
    out = subprocess.run([cc, "-dumpfullversion", "-dumpversion"], capture_output=True, text=True).stdout.strip()
    ver = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout
    return int(out.split(".")[0]) if "clang" not in ver.lower() and out[:1].isdigit() else None


@pytest.mark.skipif(not _avx512() or _gcc_major() != 12, reason="the fusing is gcc 12's on an AVX-512 CPU")
def test_straight_line_vectoriser_fuses_the_control(cache, monkeypatch):
    """The control of the test above: the same build with gcc's straight-line vectoriser on
    (gcc 12, AVX-512: ``vfmaddsub``) gives other bits than the evaluator's."""
    vectorised = [f for f in SHIPPED if f != "-fno-tree-slp-vectorize"]
    compiled = _quaternion_values(_build_with_chain(monkeypatch, vectorised, NATIVE, _quaternion_chain(), "qchain"))
    assert not np.array_equal(compiled, _quaternion_values(_quaternion_chain()))


def _build_with_chain(monkeypatch, flags, native, f, tag):
    monkeypatch.setattr(sbc, "CFLAGS", flags)
    monkeypatch.setattr(sbc, "NATIVE_CFLAGS", native)
    funcs = sbc.compile_functions([f], tag)
    assert funcs["__evaluator__"] == sbc.EVALUATOR_C
    return funcs[f.name()]


# -- inputs tested for null once per function -----------------------------------------------
def _trig() -> ca.Function:
    x, y = ca.SX.sym("x", 3), ca.SX.sym("y", 3)
    return ca.Function("sb_trig", [x, y], [ca.sin(x) * ca.cos(x) + 2 * y + x])


def test_generated_functions_test_each_input_once():
    cg = ca.CodeGenerator("t.c", {"with_header": False})
    cg.add(_trig())
    raw = cg.dump()
    src = sbc.hoist_inputs(raw)
    assert (len(sbc._INPUT_READ.findall(raw)) > 0, len(sbc._INPUT_READ.findall(src))) == (True, 0)
    assert src.count("const casadi_real *sb_in") == 2  # x and y, once each


@pytest.mark.parametrize("empty", [0, 1], ids=["x_empty", "y_empty"])
def test_a_null_input_still_reads_as_zeros(cache, empty):
    """casadi passes an empty argument as a null pointer, meaning zeros: the compiled function
    gives the evaluator's numbers with either input empty."""
    f = _trig()
    g = sbc.compile_functions([f], "trig")["sb_trig"]
    args = [ca.DM([0.5, 1.0, 2.0]), ca.DM([1.0, 2.0, 3.0])]
    args[empty] = ca.DM()
    assert np.asarray(g(*args)).ravel().tolist() == np.asarray(f(*args)).ravel().tolist()


# -- end to end: the compiled fused loop is the expression ---------------------------------
_LOOP = """
import json, sys
import stationbed
scene = stationbed.load_scene(sys.argv[1])
tr = stationbed.simulate(scene, duration=float(sys.argv[2]), fused=True)
print(json.dumps({"evaluator": tr.meta.get("evaluator"), "fused": tr.meta["summary"]["fused"],
                  "data": tr.data.tolist()}))
"""


def _fly(no_compile: bool) -> dict:
    env = dict(os.environ)
    env.pop(sbc.NO_COMPILE_ENV, None)
    if no_compile:
        env[sbc.NO_COMPILE_ENV] = "1"
    out = subprocess.run([sys.executable, "-c", _LOOP, str(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml"), str(LOOP_S)],
                         capture_output=True, text=True, env=env, check=True, timeout=LOOP_TIMEOUT_S)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_compiled_flight_loop_gives_the_evaluators_bits():
    if sbc.compiler() is None:
        pytest.skip("no C compiler")
    compiled, vm = _fly(False), _fly(True)
    assert (compiled["evaluator"], vm["evaluator"], compiled["fused"], vm["fused"]) == (sbc.EVALUATOR_C, sbc.EVALUATOR_VM,
                                                                                    True, True)
    assert compiled["data"] == vm["data"]


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64") or shutil.which("objdump") is None,
                    reason="reads x86 machine code with objdump")
def test_the_fused_loops_libraries_have_no_fused_multiply_add(monkeypatch):
    """The truth-fed and the flight loops' libraries, disassembled: not one fused multiply-add
    (gcc's vectorisers may emit one despite ``-ffp-contract=off``: the flags above must stop
    them, for every loop the shipped scenes build)."""
    if sbc.compiler() is None:
        pytest.skip("no C compiler")
    import stationbed
    from stationbed.run import composed

    libs = {}
    real = sbc.compile_functions

    def recording(mod):
        def compile_functions(functions, tag, extra_c=""):
            out = real(functions, tag, extra_c)
            libs.setdefault(mod.__name__, []).append(out.get("__lib__"))
            return out
        return compile_functions

    for mod in (composed,):  # the composed loop flies both (issue 33)
        monkeypatch.setattr(mod, "_CHUNKS", {})  # built (or loaded from the cache) again, here
        monkeypatch.setattr(mod, "compile_functions", recording(mod))
    estimated = stationbed.load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml")
    for scene in (estimated, estimated.replace({"sensor": [], "estimator": None})):
        stationbed.simulate(scene, duration=1.0, fused=True)
    # both loops built (the default rate's probe, when not on disk yet, builds more: checked too)
    assert sorted(libs) == [composed.__name__] and len(libs[composed.__name__]) == 2, libs
    for lib in [lib for found in libs.values() for lib in found]:
        assert lib, libs
        asm = subprocess.run(["objdump", "-d", "--no-show-raw-insn", lib], capture_output=True, text=True, check=True).stdout
        assert FMA_MNEMONIC.findall(asm) == [], lib
