"""The compile cache and its fallbacks (issue 12, items 5-9; stationbed/core/compile.py).

Claims:

* a cache folder that other users can write is refused: a library planted there is never
  loaded, the run uses casadi's virtual machine and says why in one line (item 5);
* a cached library cut short or overwritten is rebuilt before it is loaded: the next run works
  and gives the same numbers (item 6; in child processes, since loading such a file used to
  end the process with a bus error);
* ``STATIONBED_CACHE`` naming a regular file, a path that cannot be created, a read-only folder,
  or a cache whose files cannot be written: the run falls back to casadi's evaluator, with one
  line naming the variable (item 7);
* without a working C compiler the run says so once and records the evaluator it used, in the
  System and in the trajectory's ``meta["evaluator"]`` (item 8);
* a structure with 60 or 200 arrays gets a library file name the file system takes (item 9);
* the generated C of a DOP853 system grows by a bounded amount per array: its stages call one
  compiled RHS instead of holding a copy of it each (item 9; slow: with the compile time of 32
  arrays).

Every test points ``STATIONBED_CACHE`` at its own temporary folder.
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import stationbed.run.system as system_mod
from scenes import RIGID
from stationbed import simulate
from stationbed.core import compile as sbc
from stationbed.model import Structure
from stationbed.run.system import build_system
from stationbed.scene import scene_from_dict

#: the file-name limit of the usual file systems (ext4, xfs, btrfs, tmpfs) [bytes]
NAME_MAX = 255
#: the casadi VM and the generated C run the same operations; the DOP853 step control is the
#: same algorithm in C and in Python (tests/test_integrators.py): agreement to round-off
VM_RTOL = 1e-12
#: generated C per added array of a dop853 system with the RHS called by the stages (measured
#: 19 kB; 95 kB when every stage inlined it: benchmarks/bench_compile.py) [bytes]
C_BYTES_PER_ARRAY = 40_000


# ---------------------------------------------------------------------------------------------
# fixtures and helpers
# ---------------------------------------------------------------------------------------------
@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private cache folder (mode 700) in ``STATIONBED_CACHE``, compiling allowed, and the
    once-per-process notices forgotten."""
    d = tmp_path / "cache"
    d.mkdir(mode=0o700)
    monkeypatch.setenv(sbc.CACHE_ENV, str(d))
    monkeypatch.delenv(sbc.NO_COMPILE_ENV, raising=False)
    monkeypatch.setattr(sbc, "_SAID", set(), raising=False)
    return d


@pytest.fixture
def notices():
    """The warnings the ``stationbed`` logger emits during the test (its own handler, so that
    a handler another part of the package installs does not hide them)."""
    records: list[logging.LogRecord] = []

    class _Keep(logging.Handler):
        def emit(self, record):
            records.append(record)

    logger = logging.getLogger("stationbed")
    handler = _Keep(level=logging.WARNING)
    logger.addHandler(handler)
    try:
        yield records
    finally:
        logger.removeHandler(handler)


@pytest.fixture
def fresh_systems(monkeypatch):
    """Forget the systems built in this process (each test builds its own)."""
    monkeypatch.setattr(system_mod, "_SYSTEMS", {})


def _probe(value: float | None = None) -> ca.Function:
    """``probe(x) = x² + 1``, or a planted impostor of the same name returning ``value``."""
    x = ca.SX.sym("x")
    return ca.Function("sb_probe", [x], [x * x + 1.0 if value is None else 0.0 * x + value])


def _evaluate(funcs: dict, x: float = 3.0) -> float:
    return float(funcs["sb_probe"](x))


def _rigid_dict() -> dict:
    """A tumbling rigid body, 20 s (the smallest system: quick to compile)."""
    d = copy.deepcopy(RIGID)
    d["initial"]["omega_BN_B"] = [0.01, -0.02, 0.03]
    d["simulation"]["duration"] = 20.0
    return d


def _rigid_scene():
    return scene_from_dict(_rigid_dict())


def _libraries(folder: Path) -> list[Path]:
    return sorted(folder.glob("sb_*.so"))


def _plant(lib: Path, planted_bytes: bytes) -> None:
    """Replace a cached library, with a digest file that matches (an attacker who can write
    the folder can write both). A new file moved into place: this process may have the old
    one mapped (rewriting a mapped library in place is a bus error)."""
    tmp = lib.with_name(lib.name + ".planted")
    tmp.write_bytes(planted_bytes)
    os.replace(tmp, lib)
    lib.with_name(lib.name + ".sha256").write_text(hashlib.sha256(planted_bytes).hexdigest() + "\n")


def _array_scene_dict(n: int) -> dict:
    """A rigid station with ``n`` sun-tracking arrays on a ring, in orbit (gravity gradient)."""
    apps = []
    for k in range(n):
        ang = 2.0 * np.pi * k / n
        apps.append({
            "name": f"a{k}",
            "mass": 3000.0,
            "inertia": [[2.25e5, 0.0, 0.0], [0.0, 3.6e4, 0.0], [0.0, 0.0, 2.61e5]],
            "cm": [float(20.0 * np.cos(ang)), float(25.0 * np.sin(ang)), -60.0],
            "alpha": {"a0": 0.0, "rate": -0.0011313},
            "beta": {"a0": 0.25},
        })
    return {
        "name": f"arrays_{n}",
        "simulation": {"duration": 100.0, "formulation": "momentum", "integrator": "dop853"},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 2.2e5, "inertia": [[9.1e7, 0.0, 0.0], [0.0, 8.7e7, 0.0], [0.0, 0.0, 7.5e6]], "cm": [0.0, 0.0, 10.0]},
        "appendage": apps,
        "orbit": {"altitude": 4.0e5, "inclination": 0.5, "u0": 0.0, "gravity_gradient": True},
    }


# a run in a child process: a library that crashes the loader must not take pytest with it
_CHILD = textwrap.dedent(
    """
    import json, sys
    from stationbed import simulate
    from stationbed.scene import scene_from_dict
    tr = simulate(scene_from_dict(json.loads(sys.argv[1])))
    print(json.dumps({"evaluator": tr.meta.get("evaluator"), "data": tr.data.tolist()}))
    """
)


def _run_child(cache_dir: Path, scene: dict, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, **{sbc.CACHE_ENV: str(cache_dir)})
    env.pop(sbc.NO_COMPILE_ENV, None)
    return subprocess.run(
        [sys.executable, "-c", _CHILD, json.dumps(scene)], env=env, cwd=cwd, capture_output=True, text=True, timeout=600
    )


@pytest.fixture(scope="module")
def built_cache(tmp_path_factory):
    """A cache holding the libraries of the rigid scene, and that run's output (compiled once
    for the module, in a child process)."""
    d = tmp_path_factory.mktemp("built") / "cache"
    d.mkdir(mode=0o700)
    res = _run_child(d, _rigid_dict(), d.parent)
    assert res.returncode == 0, res.stderr
    return d, json.loads(res.stdout)


def _copy_cache(src: Path, dst: Path) -> None:
    """The libraries of ``src`` into the (empty, private) folder ``dst``."""
    for f in src.iterdir():
        shutil.copy2(f, dst / f.name)


# ---------------------------------------------------------------------------------------------
# item 5: a cache folder others can write is refused
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", [0o777, 0o770], ids=["others-write", "group-writes"])
def test_library_planted_in_a_cache_others_can_write_is_never_loaded(cache, tmp_path, monkeypatch, mode):
    lib = Path(sbc.compile_functions([_probe()], "probe")["__lib__"])  # the genuine one
    elsewhere = tmp_path / "attacker"
    elsewhere.mkdir(mode=0o700)
    monkeypatch.setenv(sbc.CACHE_ENV, str(elsewhere))
    impostor = Path(sbc.compile_functions([_probe(42.0)], "probe")["__lib__"])
    _plant(lib, impostor.read_bytes())  # same function name, same file name, matching digest
    monkeypatch.setenv(sbc.CACHE_ENV, str(cache))
    cache.chmod(mode)
    funcs = sbc.compile_functions([_probe()], "probe")
    assert (_evaluate(funcs), funcs.get("__lib__")) == (10.0, None)


def test_run_with_a_cache_others_can_write_uses_casadi_vm(built_cache, cache, fresh_systems):
    src, compiled = built_cache
    _copy_cache(src, cache)
    for lib in _libraries(cache):
        _plant(lib, b"\x7fELF planted")
    cache.chmod(0o777)
    tr = simulate(_rigid_scene())
    assert tr.meta["evaluator"] == sbc.EVALUATOR_VM
    np.testing.assert_allclose(tr.data, compiled["data"], rtol=VM_RTOL, atol=0.0)


def test_cache_others_can_write_is_refused_in_one_line_naming_the_variable(cache, notices):
    cache.chmod(0o777)
    for _ in range(2):
        sbc.compile_functions([_probe()], "probe")
    assert [sbc.CACHE_ENV in r.getMessage() and "writable by other users" in r.getMessage() for r in notices] == [True]


# ---------------------------------------------------------------------------------------------
# item 6: a damaged library is rebuilt (child processes: the old loader died of a bus error)
# ---------------------------------------------------------------------------------------------
def _cut_in_half(lib: Path) -> None:
    data = lib.read_bytes()
    lib.write_bytes(data[: len(data) // 2])


def _overwrite_with_garbage(lib: Path) -> None:
    lib.write_bytes(np.random.default_rng(12).integers(0, 256, lib.stat().st_size, dtype=np.uint8).tobytes())


@pytest.mark.parametrize("damage", [_cut_in_half, _overwrite_with_garbage], ids=["cut-in-half", "garbage"])
def test_damaged_library_is_rebuilt_and_gives_the_same_numbers(built_cache, tmp_path, damage):
    src, first = built_cache
    d = tmp_path / "damaged"
    d.mkdir(mode=0o700)
    _copy_cache(src, d)
    libs = _libraries(d)
    assert libs, "the first run left no library to damage"
    for lib in libs:
        damage(lib)
    res = _run_child(d, _rigid_dict(), tmp_path)
    assert res.returncode == 0, f"exit {res.returncode}: {res.stderr[-2000:]}"
    again = json.loads(res.stdout)
    assert (again["evaluator"], again["data"]) == (sbc.EVALUATOR_C, first["data"])


# ---------------------------------------------------------------------------------------------
# item 7: an unusable cache falls back to casadi's evaluator, said in one line
# ---------------------------------------------------------------------------------------------
def _regular_file(tmp_path: Path) -> Path:
    f = tmp_path / "a_file"
    f.write_text("not a folder\n")
    return f


def _under_a_regular_file(tmp_path: Path) -> Path:
    return _regular_file(tmp_path) / "cache"  # cannot be created, even by root


def _read_only_folder(tmp_path: Path) -> Path:
    if os.geteuid() == 0:
        pytest.skip("root writes into a read-only folder (the path under a regular file covers root)")
    d = tmp_path / "read_only"
    d.mkdir(mode=0o500)
    return d


UNUSABLE = [_regular_file, _under_a_regular_file, _read_only_folder]
UNUSABLE_IDS = ["regular-file", "under-a-regular-file", "read-only-folder"]


@pytest.mark.parametrize("where", UNUSABLE, ids=UNUSABLE_IDS)
def test_unusable_cache_falls_back_to_casadi_vm(cache, tmp_path, monkeypatch, where):
    monkeypatch.setenv(sbc.CACHE_ENV, str(where(tmp_path)))
    funcs = sbc.compile_functions([_probe()], "probe")
    assert (_evaluate(funcs), funcs["__evaluator__"]) == (10.0, sbc.EVALUATOR_VM)


@pytest.mark.parametrize("where", UNUSABLE, ids=UNUSABLE_IDS)
def test_unusable_cache_is_said_in_one_line_naming_the_variable(cache, tmp_path, monkeypatch, notices, where):
    monkeypatch.setenv(sbc.CACHE_ENV, str(where(tmp_path)))
    for _ in range(2):
        sbc.compile_functions([_probe()], "probe")
    assert [sbc.CACHE_ENV in r.getMessage() for r in notices] == [True]


_CHILD_NO_WRITES = textwrap.dedent(
    """
    import json, logging, resource, signal
    import casadi as ca
    from stationbed.core import compile as sbc
    said = []
    class Keep(logging.Handler):
        def emit(self, record):
            said.append(record.getMessage())
    logging.getLogger("stationbed").addHandler(Keep(level=logging.WARNING))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))  # no file can grow: a full disk, for root too
    x = ca.SX.sym("x")
    funcs = sbc.compile_functions([ca.Function("sb_probe", [x], [x * x + 1.0])], "probe")
    print(json.dumps({"value": float(funcs["sb_probe"](3.0)), "evaluator": funcs["__evaluator__"], "said": said}))
    """
)


def test_cache_whose_files_cannot_be_written_falls_back_in_one_line(cache, tmp_path):
    env = dict(os.environ, **{sbc.CACHE_ENV: str(cache)})
    res = subprocess.run([sys.executable, "-c", _CHILD_NO_WRITES], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    out = json.loads(res.stdout)
    assert (out["value"], out["evaluator"], [sbc.CACHE_ENV in s for s in out["said"]]) == (10.0, sbc.EVALUATOR_VM, [True])


# ---------------------------------------------------------------------------------------------
# item 8: no working C compiler: said once, the evaluator recorded
# ---------------------------------------------------------------------------------------------
def _no_compile_switch(monkeypatch, tmp_path):
    monkeypatch.setenv(sbc.NO_COMPILE_ENV, "1")


def _cc_is_false(monkeypatch, tmp_path):
    monkeypatch.setenv("CC", shutil.which("false") or "/bin/false")


def _no_cc_on_path(monkeypatch, tmp_path):
    empty = tmp_path / "empty_bin"
    empty.mkdir()
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", str(empty))


NO_COMPILER = [_no_compile_switch, _cc_is_false, _no_cc_on_path]
NO_COMPILER_IDS = ["STATIONBED_NO_COMPILE", "CC-fails", "no-cc-on-PATH"]


@pytest.mark.parametrize("how", NO_COMPILER, ids=NO_COMPILER_IDS)
def test_no_compiler_is_said_once(cache, tmp_path, monkeypatch, notices, how):
    how(monkeypatch, tmp_path)
    for value in (None, 2.0):  # two different libraries wanted
        sbc.compile_functions([_probe(value)], "probe")
    assert len(notices) == 1, [r.getMessage() for r in notices]


@pytest.mark.parametrize("how", NO_COMPILER, ids=NO_COMPILER_IDS)
def test_run_without_compiler_records_casadi_vm(cache, tmp_path, monkeypatch, fresh_systems, how):
    how(monkeypatch, tmp_path)
    tr = simulate(_rigid_scene())
    assert (tr.meta["evaluator"], build_system(Structure.of(_rigid_scene()), "momentum", "dop853").evaluator) == (
        sbc.EVALUATOR_VM,
        sbc.EVALUATOR_VM,
    )


def test_compiled_run_records_compiled_c(built_cache, cache, fresh_systems):
    _copy_cache(built_cache[0], cache)
    assert simulate(_rigid_scene()).meta["evaluator"] == sbc.EVALUATOR_C


# ---------------------------------------------------------------------------------------------
# item 9: many arrays
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n_arrays", [60, 200])
def test_many_arrays_get_a_library_name_the_file_system_takes(cache, n_arrays):
    key = Structure.of(scene_from_dict(_array_scene_dict(n_arrays))).key
    funcs = sbc.compile_functions([_probe()], f"momentum_dop853_{key}")  # the tag build_system gives
    lib = Path(funcs.get("__lib__", ""))
    assert (funcs["__evaluator__"], len(lib.name.encode()) <= NAME_MAX) == (sbc.EVALUATOR_C, True)


def _generated_c_bytes(n_arrays: int) -> int:
    """Size of the C generated for the dop853 momentum system of ``n_arrays`` arrays."""
    system = build_system(Structure.of(scene_from_dict(_array_scene_dict(n_arrays))), "momentum", "dop853")
    cg = ca.CodeGenerator("sb_size.c", {"with_header": False})
    for f in system.sx.values():
        cg.add(f)
    return len(cg.dump())


@pytest.mark.slow
def test_generated_c_grows_by_a_bounded_amount_per_array(cache, monkeypatch, fresh_systems):
    monkeypatch.setenv(sbc.NO_COMPILE_ENV, "1")  # the source is enough
    small, large = _generated_c_bytes(2), _generated_c_bytes(16)
    assert (large - small) / 14 <= C_BYTES_PER_ARRAY


@pytest.mark.slow
def test_32_arrays_compile_to_c(cache, fresh_systems):
    # the build's size is bounded by the C-bytes test above; its time (11 s measured; 101 s when
    # the stages inlined the RHS) is a benchmark number (benchmarks/bench_compile.py), not a test
    system = build_system(Structure.of(scene_from_dict(_array_scene_dict(32))), "momentum", "dop853")
    assert system.evaluator == sbc.EVALUATOR_C
