"""``margins`` on any law (issue 32 item 6): a law written in Python only is linearised by central
differences of its update (it was refused), and a scene flown on sensors says what the loop,
closed on the truth, leaves out.

Truths: for ``pd`` (which has a symbolic form) the exact Jacobian of that form (casadi AD) and
the margins it gives; for ``example_hold`` (Python only) in deep space, the closed-loop poles of
``θ̈ = -(kp θ + kd θ̇)`` per axis, the roots of ``s² + kd s + kp``.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from scenes import ROOT
from stationbed import load_scene
from stationbed.analysis.margins import loop_analysis
from stationbed.cli import main
from stationbed.scene import scene_from_dict

#: K by central differences against the exact one, relative to K's largest entry: the step is
#: ε^(1/3) x max(|z|, 1) = 6e-6 (margins.FD_REL), so the truncation error h² |v‴| / 6 is ~6e-12
#: relative where the law's third derivative is of order its first (pd's quaternion products and
#: its rate limit, inactive at the point), and the round-off ε |v| / h ~ 4e-11 relative. Measured
#: on iss_lvlh_hold: 2e-14 (pd is nearly linear there).
K_FD_RTOL = 1e-8
#: Margins from the two K: a relative change δ of the loop gain moves a margin by ~δ (the
#: crossing frequencies and gains are smooth in K); python-control's own searches are ~1e-9.
MARGIN_RTOL = 1e-6
#: example_hold's poles: the plant's θ, δω are exactly the law's e, ω - ω_ref, so the closed loop
#: is the textbook one; K is K_FD_RTOL off, an eigenvalue of a 2x2 block moves as much.
POLE_RTOL = 1e-7
KP, KD = 4.0e-5, 1.2e-2  # 1/s², 1/s: example_hold's gains
MARGIN_KEYS = ("gain_margin_down", "phase_margin_deg", "crossover_rad_s", "disk_margin", "bandwidth_rad_s",
               "sensitivity_peak")


@pytest.fixture(scope="module")
def iss_loops():
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    return loop_analysis(scene, gain="symbolic"), loop_analysis(scene, gain="numerical")


def test_numerical_gain_of_pd_is_its_symbolic_jacobian(iss_loops):
    exact, fd = iss_loops
    assert (exact.gain, fd.gain) == ("symbolic", "numerical")
    assert_allclose(fd.K, exact.K, rtol=0, atol=K_FD_RTOL * np.abs(exact.K).max())


@pytest.mark.parametrize("channel", [0, 1, 2], ids=["x", "y", "z"])
def test_numerical_gain_of_pd_gives_its_margins(iss_loops, channel):
    exact, fd = iss_loops
    for key in MARGIN_KEYS:
        assert_allclose(fd.channels[channel][key], exact.channels[channel][key], rtol=MARGIN_RTOL, err_msg=key)


def test_python_only_law_is_linearised_numerically():
    """example_hold (no symbolic form; refused before) holding an inertial attitude in deep space."""
    scene = scene_from_dict({
        "name": "hold_python",
        "simulation": {"duration": 10.0, "integrator": "rk4", "step": 0.1},
        "body": {"mass": 4.0e5, "inertia": [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]],
                 "cm": [0.0, 0.0, 0.0]},  # kg m²
        "controller": {"name": "example_hold", "period": 0.1, "params": {"reference": "inertial", "kp": KP, "kd": KD}},
    })
    la = loop_analysis(scene)
    assert la.gain == "numerical"
    expect = np.repeat(np.roots([1.0, KD, KP]), 3)
    def order(p):
        return sorted(p, key=lambda s: (s.imag > 0, s.real))

    assert_allclose(order(la.poles), order(expect), rtol=POLE_RTOL)


def test_margins_says_what_a_sensed_scene_leaves_out(tmp_path, capsys):
    """iss_lvlh_hold_estimated flies pd on two gyros, two star trackers and an MEKF: the margins are
    of pd on the truth, and the output (printed and margins.json) says so, naming them."""
    assert main(["margins", str(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml"), "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if "left out" in x)
    for part in ("closed on the true state", "gyro rga1, rga2", "star_tracker st1, st2", "estimator mekf", "delay"):
        assert part in line
    import json

    assert json.loads((tmp_path / "margins.json").read_text())["left_out"] == ["gyro rga1, rga2", "star_tracker st1, st2",
                                                                                "estimator mekf"]


def test_margins_on_the_truth_leaves_nothing_out():
    assert loop_analysis(load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")).left_out == []


def test_an_fmu_law_is_linearised_in_place_and_gives_pds_margins(tmp_path):
    """The pd FMU of tests/test_fmu.py (it cannot be copied: called in place, its command at the
    point checked unchanged after the differences) gives the symbolic pd's margins."""
    pytest.importorskip("pythonfmu", reason="pythonfmu (builds the test FMU) is not installed")
    from test_fmu import PD_PARAMS, _build, fmu_scene, pd_scene  # noqa: PLC0415 - needs pythonfmu

    fmu = loop_analysis(fmu_scene(_build(2, tmp_path)))
    pd = loop_analysis(scene_from_dict(pd_scene({"name": "pd", "params": PD_PARAMS})))
    assert (fmu.gain, pd.gain) == ("numerical", "symbolic")
    for c_fmu, c_pd in zip(fmu.channels, pd.channels):
        for key in MARGIN_KEYS:
            assert_allclose(c_fmu[key], c_pd[key], rtol=MARGIN_RTOL, err_msg=key)


class Counting:
    """A Python law that keeps a state it cannot hand over (a lock: no copy) and adds it to its
    command: a later call at the same state commands another torque."""

    name, command, period, plant, q_ref_BN = "counting", "torque", 0.1, None, None

    def __init__(self):
        import threading  # noqa: PLC0415

        self.lock, self.n = threading.Lock(), 0

    def reset(self, plant):
        self.plant = plant

    def update(self, t, meas):
        self.n += 1
        return tuple(-1.0e6 * meas.omega_BN_B + self.n)  # N m


def test_a_law_that_keeps_a_state_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"^margins: controller 'counting' gave another command at the same state"):
        loop_analysis(load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml"), Counting())


def test_an_open_loop_law_is_refused_naming_it():
    """torque_command (sgcmg_singularity) commands a schedule: no loop (it failed on a reshape)."""
    with pytest.raises(ValueError, match=r"^margins: controller 'torque_command' does not feed back the state"):
        loop_analysis(load_scene(ROOT / "scenarios" / "sgcmg_singularity.toml"))
