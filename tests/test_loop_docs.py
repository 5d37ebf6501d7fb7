"""docs/loop.md's code is real: the ISS-like sensor set is a valid scene table that builds a
filter, and the worked example (a coarse sun sensor written as one plug-in) obeys its physics.

Truths used: the cosine law computed with ``scipy.spatial.transform.Rotation`` (not the
library's quaternion code), zero behind the cell and in shadow; the noise variance in its
chi-squared band (scipy.stats).
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from stationbed.loop import TRUTH, Mekf, Sensor, build_sensors, noise_rng
from stationbed.scene import sensing_from_dict

DOC = Path(__file__).resolve().parents[1] / "docs" / "loop.md"
#: float64 round-off of a rotation and a dot product of unit vectors
ROUNDOFF = 1e-14
#: two-sided miss probability of the noise-variance band
ALPHA = 1e-3


def _block(lang: str, marker: str) -> str:
    blocks = re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(), flags=re.S)
    found = [b for b in blocks if marker in b]
    assert len(found) == 1, f"docs/loop.md: expected one ```{lang} block with {marker!r}, found {len(found)}"
    return found[0]


@pytest.fixture(scope="module")
def example():
    ns: dict = {}
    exec(compile(_block("python", "class CoarseSunSensor"), str(DOC), "exec", dont_inherit=True), ns)
    return ns["CoarseSunSensor"], ns["CoarseSunTable"]


def test_documented_iss_set_is_valid_and_builds_a_filter():
    sensing = sensing_from_dict(tomllib.loads(_block("toml", "[estimator]")), source="docs/loop.md")
    sensors = build_sensors(sensing.sensor)
    assert [s.kind for s in sensors] == ["gyro", "star_tracker", "star_tracker"]
    mekf = Mekf.from_sensors(sensing.estimator, sensors)
    assert mekf.every == [10, 10]  # heads at 1 Hz, gyro at 10 Hz
    assert mekf.state.get(mekf.initial([1.0, 0, 0, 0]), "P")[0, 0] == pytest.approx(1e-6)  # (1e-3 rad)²


def test_worked_example_is_a_sensor_with_the_cosine_law(example):
    cls, table = example
    assert issubclass(cls, Sensor)
    s = cls(table(kind="coarse_sun", name="css", period=1.0, normal_B=[0.0, 0.0, -2.0]))
    n = 400
    rots = Rotation.random(n, random_state=3)  # C_NB
    gen = np.random.default_rng(4)
    sun = gen.normal(size=(n, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    shadow = np.where(np.arange(n) % 4 == 0, 0.0, np.where(np.arange(n) % 4 == 1, 0.5, 1.0))
    truth = np.zeros((n, TRUTH.size))
    x, y, z, w = rots.as_quat().T
    truth[:, TRUTH.slice("q_BN")] = np.stack([w, x, y, z], axis=1)
    truth[:, TRUTH.slice("sun_N")] = sun
    truth[:, TRUTH.slice("shadow")] = shadow[:, None]
    _, out = s.record(np.arange(1.0, n + 1), truth, np.zeros((n, 1)))
    sun_B = rots.inv().apply(sun)  # C_BN sun_N
    expected = shadow * np.maximum(-sun_B[:, 2], 0.0)  # the unit normal is -z_B
    assert_allclose(out[:, 0], expected, rtol=0, atol=ROUNDOFF)
    assert np.sum((expected == 0) & (shadow > 0)) > 50  # the back side was seen


def test_worked_example_noise_variance_inside_its_band(example):
    cls, table = example
    sigma = 0.01  # fraction of full scale
    s = cls(table(kind="coarse_sun", name="css", period=1.0, normal_B=[1.0, 0.0, 0.0], sigma=sigma))
    n = 3000
    truth = np.zeros((n, TRUTH.size))
    truth[:, TRUTH.slice("q_BN")] = [1.0, 0.0, 0.0, 0.0]
    truth[:, TRUTH.slice("sun_N")] = [0.6, 0.8, 0.0]
    truth[:, TRUTH.slice("shadow")] = 1.0
    _, out = s.record(np.arange(1.0, n + 1), truth, s.noise(noise_rng(5, 0), n))
    ss = np.sum((out[:, 0] - 0.6) ** 2) / sigma**2
    lo, hi = chi2.ppf([ALPHA / 2, 1 - ALPHA / 2], n)
    assert lo <= ss <= hi
