"""Every torque a scene flies is in the linear plant's point (issue 19 A2): the held ``constant``
windows enter the trim (the torque that holds the point) and the torque-equilibrium attitude, as
the same torque written as an ``orbital_harmonic`` bias (a symbolic kind) does.

Truths, written here without the analysis code: the holding torque of a rigid station at rest in
LVLH, ``τ = ω × Iω - 3n² R̂ × IR̂ - L`` (``ω = (0, -n, 0)``, ``R̂ = (0, 0, -1)`` in LVLH axes); the
TEA as the root of the same torque balance in numpy (scipy's ``fsolve``; at rest in LVLH on a
circular orbit every term is constant in B, so the orbit average is the value).
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import fsolve

from stationbed.analysis import linearize
from stationbed.scene import scene_from_dict

JEOD_I = np.array([[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]])  # kg m²
MU = 3.986004418e14  # m³/s², the scene's default
RADIUS_M = 6778137.0  # m, 400 km up
N_RAD_S = math.sqrt(MU / RADIUS_M**3)  # rad/s, mean motion of the circular orbit
L_B = [3.0, -4.0, 0.0]  # N m: a 5 N m body torque
#: round-off on 1e8-size inertias times n² ~ 1.3e-6 (torques of ~100 N m): a few ulp of ω × Iω
TRIM_ABS = 1e-9  # N m
#: the TEA: Newton's residual (1e-10 n² relative) and fsolve's xtol, on angles of ~0.1 rad
TEA_ABS = 1e-8  # rad


def scene(torque=None, cmg=False):
    d = {
        "name": "held_torque_plant",
        "simulation": {"duration": 10.0},
        "initial": {"frame": "lvlh"},
        "body": {"mass": 4.0e5, "inertia": JEOD_I.tolist(), "cm": [0.0, 0.0, 0.0]},
        "orbit": {"radius": RADIUS_M, "inclination": 0.9006, "u0": 0.3, "gravity_gradient": True},
        "torque": [] if torque is None else [torque],
    }
    if cmg:
        d["cmg"] = {"kind": "ideal"}
    return scene_from_dict(d)


CONSTANT = {"kind": "constant", "torque_B": L_B}
HARMONIC = {"kind": "orbital_harmonic", "bias_B": L_B}


def C_BO(theta):
    """DCM O -> B of the attitude θ = 2 vec(q_BO) (the plant's coordinate), written out."""
    e = 0.5 * np.asarray(theta, float)
    w = math.sqrt(1.0 - e @ e)
    x, y, z = e
    C_OB = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    return C_OB.T


def external_and_gyro(theta, L=L_B):
    """``L_gg + L - ω × Iω`` for the station at rest in LVLH at θ, B components [N m]."""
    C = C_BO(theta)
    R_B = C @ np.array([0.0, 0.0, -1.0])  # the orbit radius' direction: LVLH z is nadir
    w_B = C @ np.array([0.0, -N_RAD_S, 0.0])
    return 3 * N_RAD_S**2 * np.cross(R_B, JEOD_I @ R_B) + np.asarray(L) - np.cross(w_B, JEOD_I @ w_B)


@pytest.mark.parametrize("cmg", [False, True], ids=["no_cluster", "ideal_cmg"])
@pytest.mark.parametrize("torque", [CONSTANT, HARMONIC], ids=["constant", "harmonic_bias"])
def test_holding_torque_includes_every_torque(torque, cmg):
    """About LVLH: the trim cancels gravity gradient, gyroscopic torque and the 5 N m body torque,
    whichever kind carries it; without the torque it differs by exactly -L."""
    lin = linearize(scene(torque, cmg), "lvlh").linearization
    expect = -external_and_gyro(np.zeros(3))
    assert_allclose(lin.trim_torque, expect, rtol=0, atol=TRIM_ABS)
    bare = linearize(scene(None, cmg), "lvlh").linearization
    assert_allclose(lin.trim_torque - bare.trim_torque, -np.asarray(L_B), rtol=0, atol=TRIM_ABS)
    assert_allclose(lin.zdot0[3:6], 0.0, atol=1e-15)  # the point is held: an equilibrium


@pytest.mark.parametrize("torque", [CONSTANT, HARMONIC], ids=["constant", "harmonic_bias"])
def test_tea_balances_every_torque(torque):
    """The TEA with the 5 N m torque is the root of the torque balance (fsolve in numpy), the same
    whichever kind carries it, and not the TEA without it."""
    tea = linearize(scene(torque), "tea").linearization.tea_theta
    expect = fsolve(external_and_gyro, np.zeros(3), xtol=1e-14)
    assert_allclose(external_and_gyro(expect), 0.0, atol=1e-9)
    assert_allclose(tea, expect, rtol=0, atol=TEA_ABS)
    bare = linearize(scene(None), "tea").linearization.tea_theta
    assert np.linalg.norm(tea - bare) > 1e3 * TEA_ABS


def test_window_switching_inside_the_tea_orbit_is_refused():
    """A window that opens inside the orbit the TEA averages over: refused, naming the kind and
    the time; a window on for the whole orbit (ends beyond it) is a torque like any other."""
    win = {"kind": "constant", "torque_B": L_B, "start": 1000.0, "stop": 1200.0}
    with pytest.raises(ValueError, match=r"torque\[0\] \(kind = 'constant'\) switches at t = 1000 s"):
        linearize(scene(win), "tea")
    long = {"kind": "constant", "torque_B": L_B, "start": -1.0, "stop": 1.0e6}
    tea = linearize(scene(long), "tea").linearization.tea_theta
    assert_allclose(tea, fsolve(external_and_gyro, np.zeros(3), xtol=1e-14), rtol=0, atol=TEA_ABS)
    # about LVLH the window is frozen at t, as every time-varying term: off at t = 0, on at 1100 s
    assert_allclose(linearize(scene(win), "lvlh", t=0.0).linearization.u0[3:], 0.0)
    assert_allclose(linearize(scene(win), "lvlh", t=1100.0).linearization.u0[3:], L_B)


def test_cli_refuses_with_one_line(tmp_path):
    """The command line: one ``stationbed: error:`` line naming the torque, exit 2."""
    import subprocess
    import sys
    from pathlib import Path

    from scenes import one_error_line

    path = tmp_path / "win.toml"
    path.write_text(
        'name = "win"\n[simulation]\nduration = 10.0\n[initial]\nframe = "lvlh"\n'
        '[body]\nmass = 4.0e5\ninertia = [[1.02e8, 0, 0], [0, 0.91e8, 0], [0, 0, 1.64e8]]\n'
        '[orbit]\naltitude = 400000.0\ngravity_gradient = true\n'
        '[[torque]]\nkind = "constant"\ntorque_B = [3.0, -4.0, 0.0]\nstart = 1000.0\nstop = 1200.0\n'
    )
    exe = Path(sys.executable).parent / "stationbed"  # the installed console script
    r = subprocess.run([str(exe), "linearize", str(path), "--about", "tea",
                        "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert "kind = 'constant'" in one_error_line(r.stderr)
