"""Shared fixtures."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from scenes import RIGID


@pytest.fixture
def rigid_scene_dict():
    return copy.deepcopy(RIGID)


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
