"""Cost of the sensors and the MEKF per orbit, beside the fused closed loop (issue 20).

    python benchmarks/bench_loop.py [--repeats N] [--json PATH]

Timed side by side in one process (interleaved, median of ``--repeats`` runs each, after a warm-up
run that compiles or loads the cached build), one orbit of 55 536 ticks at 0.1 s with the
ISS-like set of docs/loop.md (a 10 Hz gyro, two 1 Hz star-tracker heads):

* ``suite``: the tick of :class:`stationbed.loop.Suite` with the MEKF, its mapaccum over the
  orbit generated as C (as a fused loop inlines it; the truth rows and the noise table prepared
  beforehand, not timed);
* ``sensors``: the same suite without the estimator;
* ``mekf``: the filter alone (heads fresh once a second), generated the same way;
* ``fused_loop``: ``simulate(iss_lvlh_hold)`` with the fused loop, the reference of the issue's
  "<= 1.5x the fused loop without them".

The ratio ``(fused_loop + suite) / fused_loop`` is what the integration would cost if it added
the suite's tick to the fused loop's unchanged; the integrated loop itself is measured by
``benchmarks/bench_estimated.py``. ``--smoke``: 200 ticks, one repeat (CI).
"""

from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

from stationbed.loop import TRUTH, Suite, SuiteNoise  # noqa: E402
from stationbed.scene import sensing_from_dict  # noqa: E402

TICK_S = 0.1  # s
N_TICKS = 55536  # one ISS orbit (5553.6 s)


def _iss_set(estimator: bool):
    text = (ROOT / "docs" / "loop.md").read_text()
    block = next(b.split("```")[0] for b in text.split("```toml\n")[1:] if "[estimator]" in b)
    data = tomllib.loads(block)
    if not estimator:
        data.pop("estimator")
    return sensing_from_dict(data, source="docs/loop.md")


def _truth(n: int) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    omega = np.array([0.0, -1.1313e-3, 0.0])  # rad/s, the LVLH hold's orbit rate
    t = TICK_S * np.arange(1, n + 1)
    rots = Rotation.from_rotvec(t[:, None] * omega)
    x, y, z, w = rots.as_quat().T
    rows = np.zeros((n, TRUTH.size))
    rows[:, TRUTH.slice("q_BN")] = np.stack([w, x, y, z], axis=1)
    rows[:, TRUTH.slice("theta_B")] = t[:, None] * omega
    rows[:, TRUTH.slice("R_N")] = [6.778e6, 0.0, 0.0]
    rows[:, TRUTH.slice("sun_N")] = [0.0, 1.0, 0.0]
    rows[:, TRUTH.slice("moon_N")] = [0.0, -1.0, 0.0]
    rows[:, TRUTH.slice("shadow")] = 1.0
    return rows


def _generated(f, accum: int, tag: str):
    """The whole orbit as generated C: ``f``'s mapaccum over N_TICKS compiled (as a fused loop
    would inline it), called through bound buffers. (``Suite.record`` maps the compiled tick
    from casadi's evaluator instead: ~2 µs of call overhead per tick, not the tick's cost.)"""
    from stationbed.core.compile import FastCall, compile_functions

    F = f.mapaccum(f"{tag}_{N_TICKS}", N_TICKS, [accum], [0])
    return FastCall(compile_functions([F], tag)[F.name()])


def _run(fc, *args):
    for arg, value in zip(fc.args, args):
        arg[:] = np.ravel(value)
    fc()
    return fc.res[0]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path)
    args = _smoke.parse(ap, argv, "200 ticks instead of an orbit, one repeat")
    global N_TICKS
    if args.smoke:
        N_TICKS = 200

    truth = _truth(N_TICKS)
    full, bare = Suite(_iss_set(True), TICK_S), Suite(_iss_set(False), TICK_S)
    w_full, w_bare = SuiteNoise(full, 1).draw(N_TICKS), SuiteNoise(bare, 1).draw(N_TICKS)
    m = full.mekf
    z = np.zeros((N_TICKS, m.inputs.size))
    z[:, m.inputs.slice("omega_B")] = [0.0, -1.1313e-3, 0.0]
    for i in range(len(m.heads)):
        z[9::10, m.inputs.slice(f"q_SN_{i}")] = [1.0, 0.0, 0.0, 0.0]
        z[9::10, m.inputs.slice(f"valid_{i}")] = 1.0
        z[9::10, m.inputs.slice(f"fresh_{i}")] = 1.0
    xf0 = m.initial([1.0, 0.0, 0.0, 0.0])

    suite_c, bare_c, mekf_c = (_generated(f, n_acc, tag) for f, n_acc, tag in (
        (full.function(), 2, "bench_suite"), (bare.function(), 2, "bench_sensors"), (m.function(), 0, "bench_mekf")))
    ks = np.arange(1, N_TICKS + 1, dtype=float)

    import stationbed

    scene = stationbed.load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml").replace(
        {"simulation.duration": N_TICKS * TICK_S})
    paths = {
        "suite": lambda: _run(suite_c, ks, ks * TICK_S, full.initial(), truth, w_full, np.tile(full.params, N_TICKS)),
        "sensors": lambda: _run(bare_c, ks, ks * TICK_S, bare.initial(), truth, w_bare, np.tile(bare.params, N_TICKS)),
        "mekf": lambda: _run(mekf_c, xf0, z, np.tile(m.params, N_TICKS)),
        "fused_loop": lambda: stationbed.simulate(scene, fused=True),
    }
    med = _smoke.interleaved(paths, args.repeats).wall  # (its warm-up compiles or loads the cached builds)
    out = {"per_orbit_s": med, "ratio_fused_plus_suite": (med["fused_loop"] + med["suite"]) / med["fused_loop"]}
    for k, v in med.items():
        print(f"{k:>11}: {v:.3f} s per orbit")
    print(f"(fused loop + suite) / fused loop = {out['ratio_fused_plus_suite']:.2f} (target <= 1.5)")
    _smoke.write_json(args.json, out)
    return out


if __name__ == "__main__":
    main()
