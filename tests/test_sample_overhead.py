"""Python per Monte Carlo sample (issue 25, item 4): the controllers' entry points, read from every
installed distribution's metadata (~4 ms), are scanned once per ``sys.path``, not once per sample.

Truth: the number of metadata scans counted at ``importlib.metadata.entry_points`` itself.
"""

from __future__ import annotations

import importlib.metadata

from stationbed.run import controller as ctl


def _counting(monkeypatch):
    calls = []
    real = importlib.metadata.entry_points

    def counted(**kw):
        calls.append(kw)
        return real(**kw)

    monkeypatch.setattr(importlib.metadata, "entry_points", counted)
    ctl._ENTRY_POINTS.clear()
    return calls


def test_entry_points_scanned_once_for_many_samples(monkeypatch):
    calls = _counting(monkeypatch)
    classes = {ctl.get_controller("pd") for _ in range(20)}
    assert len(calls) == 1 and len(classes) == 1


def test_a_new_path_is_scanned_again(monkeypatch, tmp_path):
    """A folder put on ``sys.path`` may bring a package with its own laws: scanned anew."""
    calls = _counting(monkeypatch)
    ctl.get_controller("pd")
    monkeypatch.syspath_prepend(str(tmp_path))
    ctl.get_controller("pd")
    assert len(calls) == 2
