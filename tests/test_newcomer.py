"""What a newcomer meets first (issue 19, item 19): ``--version``, the examples in ``--help``, the
web viewer's address, and the shipped example law's imports."""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

import stationbed
from stationbed.cli import WEB_BIND_DEFAULT, _parser, main
from stationbed.scene import load_scene, parse_assignments

ROOT = Path(__file__).resolve().parents[1]
STATIONBED = Path(sys.executable).parent / "stationbed"


def test_version_prints_the_package_version():
    res = subprocess.run([str(STATIONBED), "--version"], capture_output=True, text=True)
    assert res.returncode == 0
    from importlib.metadata import version

    assert res.stdout.strip() == f"stationbed {version('stationbed')}" == f"stationbed {stationbed.__version__}"


def _set_examples(cmd: str) -> tuple[str, list[str]]:
    sub = next(a for a in _parser()._actions if a.dest == "cmd").choices[cmd]
    text = " ".join(sub.format_help().split())  # argparse wraps lines anywhere
    found = re.findall(r"--set '?([A-Za-z_][\w.\[\]]*=[^,' ]+)", text)
    return text, [ex for ex in found if not ex.startswith("KEY.PATH=")]  # the metavar


@pytest.mark.parametrize("cmd", ["run", "check"])
def test_help_set_examples_apply_to_the_scenes_it_names(cmd):
    """The help's ``--set`` examples: an array example says which shipped scenes have that array,
    and every example changes a value of each of those scenes (the changed scene validates)."""
    text, examples = _set_examples(cmd)
    assert len(examples) >= 3
    globs = re.findall(r"in (scenarios/\S+\.toml)", text)
    assert globs, "the help does not say which scenes its array example is for"
    scenes = sorted({p for g in globs for p in ROOT.glob(g)})
    assert len(scenes) >= 3
    for ex in examples:
        for path in scenes:
            load_scene(path).replace(parse_assignments([ex]), source=str(path))  # raises SceneError if not


def fake_viewer(tmp_path) -> Path:
    exe = tmp_path / "fake_rerun"
    exe.write_text(f'#!/bin/sh\nprintf "%s\\n" "$@" > "{tmp_path}/argv.txt"\nexit 0\n')
    exe.chmod(0o755)
    return exe


@pytest.fixture
def rrd(tmp_path):
    f = tmp_path / "x.rrd"
    f.write_bytes(b"RRF2" + bytes(60))  # the magic is all replay checks before starting the viewer
    return f


@pytest.mark.parametrize("extra, bind", [([], WEB_BIND_DEFAULT), (["--bind", "0.0.0.0"], "0.0.0.0")],
                         ids=["localhost_by_default", "asked"])
def test_replay_web_binds_to_localhost_unless_asked(tmp_path, rrd, monkeypatch, extra, bind):
    monkeypatch.setenv("STATIONBED_RERUN", str(fake_viewer(tmp_path)))
    assert main(["replay", str(rrd), "--web", *extra]) == 0
    argv = (tmp_path / "argv.txt").read_text().splitlines()
    assert argv == ["--web-viewer", "--bind", bind, str(rrd)]
    assert WEB_BIND_DEFAULT == "127.0.0.1"


def test_replay_bind_without_web_is_refused(tmp_path, rrd, monkeypatch, capsys):
    monkeypatch.setenv("STATIONBED_RERUN", str(fake_viewer(tmp_path)))
    assert main(["replay", str(rrd), "--bind", "0.0.0.0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("stationbed: error: --bind") and "--web" in err
    assert not (tmp_path / "argv.txt").exists()


def _stationbed_imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    return [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and (n.module or "").startswith("stationbed")]


def test_example_hold_imports_only_the_public_namespace():
    """controllers/example_hold.py is the guide's long form: it imports from ``stationbed`` as the
    README's guide does, and every name it imports is in ``stationbed.__all__``."""
    path = ROOT / "controllers" / "example_hold.py"
    assert set(_stationbed_imports(path)) == {"stationbed"}
    tree = ast.parse(path.read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module == "stationbed" for a in n.names]
    assert names and set(names) <= set(stationbed.__all__)
