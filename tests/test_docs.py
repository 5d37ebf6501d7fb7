"""The documentation runs as printed (issue 37, items 2 and 4): the site builds strictly, and every
command and Python block of README.md and docs/**/*.md runs, so a snippet cannot rot.

What is run, per Markdown file, in the file's order, in one scratch folder per file (``scenarios``,
``controllers``, ``tests`` and ``docs`` linked into it, so the printed relative paths hold and every
output lands in the scratch folder):

* a ```sh (or bash, shell, console) block: every ``stationbed ...`` command in it (a line ending in
  ``\\`` continues it; ``# ...`` comments are the shell's); any other command in such a block (``make``,
  ``pip``, ``dask``) makes the block one the test cannot run, and it must say why (``skip``, below);
* a ```text block (or one without a language): its ``$ stationbed ...`` lines, a transcript's
  commands (the lines after them are output, not compared: the numbers are the sections' own
  measurements); a block without a language that holds commands must say which it is (sh or text);
* a ```python block: written to a file and run with this interpreter.

Long runs are made cheap only where the Markdown says so, in an HTML comment on the line before the
block (invisible on GitHub and on the site), so the reader sees what the test changes:

    <!-- docs-test: replace("--n 1000", "--n 2") exit(1) -->
    <!-- docs-test: skip("starts a long-running service") -->
    <!-- docs-test: setup("import numpy as np; x = np.zeros(43)") -->

``replace(old, new)`` edits the block's text before it runs (``old`` must occur: a stale tag
fails), ``exit(k)`` is the status every command must end with (default 0), ``setup(code)`` runs
before a Python block, and ``skip(reason)`` runs nothing and must give a reason. A README block
printed the same on a page of the site runs there (once). An indented code block holding a
command fails the test: fence it.
"""

from __future__ import annotations

import ast
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md"))
FILES = PAGES + [ROOT / "README.md"]
#: folders the printed commands name relative to the checkout, linked into each scratch folder
LINKED = ("scenarios", "controllers", "tests", "docs")
SHELL_LANGS = {"sh", "bash", "shell", "console"}
TEXT_LANGS = {"", "text"}
TAG = re.compile(r"<!--\s*docs-test:(.*?)-->", re.S)
#: one command's wall-time limit [s]: the cheapest overrides keep every command to a few seconds;
#: a run that takes this long means a block lost its override
COMMAND_TIMEOUT_S = 240


@dataclass
class Block:
    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    body: str
    tags: dict = field(default_factory=dict)

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def parse_tags(text: str, where: str) -> dict:
    """``replace("a", "b") exit(1) skip("why") setup("code")`` -> {"replace": [(a, b)], ...}."""
    tags: dict = {"replace": []}
    for name, args in re.findall(r"(\w+)\((.*?)\)(?=\s*(?:\w+\(|$))", text.strip(), re.S):
        values = ast.literal_eval(f"({args},)") if args.strip() else ()
        if name == "replace" and len(values) == 2:
            tags["replace"].append(values)
        elif name in ("skip", "setup") and len(values) == 1 and str(values[0]).strip():
            tags[name] = values[0]
        elif name == "exit" and len(values) == 1:
            tags["exit"] = int(values[0])
        else:
            raise ValueError(f"{where}: docs-test tag {name}({args}) not understood")
    return tags


def fenced_blocks(path: Path) -> list[Block]:
    lines = path.read_text().splitlines()
    out, i = [], 0
    while i < len(lines):
        m = re.match(r"^(\s*)(```+)\s*([\w+-]*)", lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = m.groups()
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            j += 1
        body = "\n".join(ln[len(indent):] if ln.startswith(indent) else ln for ln in lines[i + 1 : j])
        k = i - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        tag = TAG.search(lines[k]) if k >= 0 else None
        tags = parse_tags(tag.group(1), f"{path.name}:{k + 1}") if tag else {"replace": []}
        out.append(Block(path, i + 1, lang.lower(), body + "\n", tags))
        i = j + 1
    return out


def indented_commands(path: Path) -> list[str]:
    """Commands in indented (unfenced) code blocks: they would escape the test."""
    bad, fence = [], False
    prev_blank = True
    for n, ln in enumerate(path.read_text().splitlines(), 1):
        if ln.lstrip().startswith("```"):
            fence = not fence
        elif not fence and prev_blank and re.match(r"^ {4,}(\$ )?stationbed ", ln):
            bad.append(f"{path.relative_to(ROOT)}:{n}")
        prev_blank = not ln.strip() or (prev_blank and ln.startswith("    "))
    return bad


def commands(block: Block) -> list[str]:
    """The ``stationbed`` commands of a shell or transcript block; ValueError naming a command
    the test cannot run (a shell block's ``make``, ``pip``, ...)."""
    shell = block.lang in SHELL_LANGS
    out, cur = [], None
    for ln in block.body.splitlines():
        s = ln.strip()
        if cur is not None:
            cur += " " + s.rstrip("\\").strip()
            if not s.endswith("\\"):
                out.append(cur)
                cur = None
            continue
        if not shell:
            if not s.startswith("$ "):
                continue  # a transcript's output
            s = s[2:]
        if not s or s.startswith("#"):
            continue
        if not s.startswith("stationbed "):
            raise ValueError(f"{block.where}: '{s.split()[0]}' is no stationbed command")
        if s.endswith("\\"):
            cur = s.rstrip("\\").strip()
        else:
            out.append(s)
    return out


def runnable(block: Block) -> bool:
    if block.lang == "python":
        return True
    if block.lang in SHELL_LANGS:
        return True
    return block.lang in TEXT_LANGS and bool(re.search(r"^\s*\$ stationbed ", block.body, re.M))


def page_blocks() -> set[str]:
    return {b.body for p in PAGES for b in fenced_blocks(p)}


def blocks_of(path: Path) -> list[Block]:
    """The blocks of ``path`` that run (or say why not); a README block printed on a page runs there."""
    seen = page_blocks() if path.name == "README.md" else set()
    return [b for b in fenced_blocks(path) if runnable(b) and b.body not in seen]


def apply_replacements(block: Block) -> str:
    text = block.body
    for old, new in block.tags["replace"]:
        assert old in text, f"{block.where}: docs-test replace({old!r}, ...) matches nothing in the block (stale tag)"
        text = text.replace(old, new)
    return text


@pytest.fixture(scope="module")
def env():
    e = dict(os.environ)
    e["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{e.get('PATH', '')}"
    e["MPLBACKEND"] = "Agg"
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):  # replay prints the viewer's commands, opens no window
        e.pop(name, None)
    # `stationbed replay --web` starts this instead of the rerun viewer (a server that would not
    # return): the command is checked up to the viewer's start, as tests/test_rerun.py does
    e["STATIONBED_RERUN"] = shutil.which("true") or "/bin/true"
    return e


def scratch(tmp_path: Path) -> Path:
    for name in LINKED:
        (tmp_path / name).symlink_to(ROOT / name)
    return tmp_path


def run(argv, cwd: Path, env: dict, where: str, expect: int):
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # its own process group: a timeout ends all of it
    try:
        out, err = proc.communicate(timeout=COMMAND_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise AssertionError(f"{where}: `{argv}` still running after {COMMAND_TIMEOUT_S} s: does the block need a cheaper override?")
    p = subprocess.CompletedProcess(argv, proc.returncode, out, err)
    dt = time.perf_counter() - t0
    shown = argv if isinstance(argv, str) else " ".join(map(str, argv))
    print(f"{dt:6.1f} s  {where}  {shown[:160]}")  # pytest -s: where the time goes
    assert p.returncode == expect, (
        f"{where}: `{shown}` exited {p.returncode} (expected {expect}) after {dt:.1f} s\n"
        f"--- stdout\n{p.stdout[-3000:]}\n--- stderr\n{p.stderr[-3000:]}"
    )


@pytest.mark.parametrize("path", FILES, ids=[str(p.relative_to(ROOT)) for p in FILES])
def test_every_block_runs_or_says_why_not(path):
    """Static: every block that looks runnable is runnable as the test reads it, or tagged skip with
    a reason; no tag is stale; no command hides in an indented block."""
    problems = indented_commands(path)
    for b in fenced_blocks(path):
        if b.lang in TEXT_LANGS and b.lang == "" and re.search(r"^\s*(\$ )?stationbed \S", b.body, re.M):
            problems.append(f"{b.where}: a block without a language holds commands: mark it sh (run) or text (a transcript)")
    for b in blocks_of(path):
        if "skip" in b.tags:
            continue
        try:
            text = apply_replacements(b)
            if b.lang != "python":
                commands(Block(b.path, b.line, b.lang, text, b.tags))
            else:
                compile(b.tags.get("setup", "") + "\n" + text, b.where, "exec")
        except (ValueError, SyntaxError, AssertionError) as exc:
            problems.append(f"{exc} (tag the block skip(\"why\") or make it runnable)")
    assert not problems, "\n".join(problems)


#: the files with a block to run (the others have only prose, tables or skipped blocks)
RUN_FILES = [p for p in FILES if any("skip" not in b.tags for b in blocks_of(p))]


@pytest.mark.slow
@pytest.mark.parametrize("path", RUN_FILES, ids=[str(p.relative_to(ROOT)) for p in RUN_FILES])
def test_blocks_run_as_printed(path, tmp_path, env):
    blocks = [b for b in blocks_of(path) if "skip" not in b.tags]
    cwd = scratch(tmp_path)
    for i, b in enumerate(blocks):
        text = apply_replacements(b)
        expect = b.tags.get("exit", 0)
        if b.lang == "python":
            script = cwd / f"block_{i}_line{b.line}.py"
            script.write_text(b.tags.get("setup", "") + "\n" + text)
            run([sys.executable, script.name], cwd, env, b.where, expect)
        else:
            for cmd in commands(Block(b.path, b.line, b.lang, text, b.tags)):
                run(["bash", "-c", cmd], cwd, env, b.where, expect)


@pytest.mark.slow
def test_site_builds_strictly(tmp_path):
    """`make docs`' build: a broken link or anchor, a page left out of the nav or a docstring
    mkdocstrings cannot read fails it (mkdocs.yml: strict, every validation a warning)."""
    mkdocs = Path(sys.executable).parent / "mkdocs"
    p = subprocess.run([str(mkdocs), "build", "--strict", "--site-dir", str(tmp_path / "site")], cwd=ROOT,
                       capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"}, timeout=300)
    assert p.returncode == 0, p.stderr[-4000:]


def test_api_reference_covers_the_public_surface():
    """Every name of ``stationbed.__all__`` has its entry in docs/reference/index.md (by the module
    it is loaded from), so a new public name cannot be left out of the reference."""
    import stationbed

    text = (DOCS / "reference" / "index.md").read_text()
    missing = [n for n in stationbed.__all__ if f"::: stationbed.{stationbed._LAZY[n]}.{n}\n" not in text]
    assert not missing, missing


def _anchors(md: Path) -> set[str]:
    """The heading anchors of a Markdown file, by the slugs the site and GitHub both make
    (mkdocs.yml: pymdownx.slugs, lower case)."""
    from pymdownx.slugs import slugify  # noqa: PLC0415

    slug, fence, out = slugify(case="lower"), False, set()
    for ln in md.read_text().splitlines():
        if ln.lstrip().startswith("```"):
            fence = not fence
        elif not fence and re.match(r"#{1,6} ", ln):
            out.add(slug(ln.lstrip("#").strip(), "-"))
    return out


def test_readme_links_resolve():
    """The README is not part of the site (its strict build checks the pages' links), so its own
    links are checked here: every relative link names a file of the checkout, and an anchor into
    a Markdown file names one of its headings."""
    text = re.sub(r"```.*?```", "", (ROOT / "README.md").read_text(), flags=re.S)
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"\w+://|mailto:", target):
            continue
        path, _, anchor = target.partition("#")
        f = ROOT / path if path else ROOT / "README.md"
        if not f.exists():
            broken.append(target)
        elif anchor and f.suffix == ".md" and anchor not in _anchors(f):
            broken.append(target)
    assert not broken, broken


#: the README is the front door (issue 37 item 3): what it is, the capabilities, set-up, a tour and
#: the scenario table; the manual is the site. Past this many lines it is becoming the manual again.
README_MAX_LINES = 250


def _scenario_rows(md: Path) -> set[str]:
    """The scenario names of a Markdown file's scenario table (first cell: `a` or `a`, `b`)."""
    names: set[str] = set()
    for ln in md.read_text().splitlines():
        m = re.match(r"\|\s*(`[\w]+`(?:\s*,\s*`[\w]+`)*)\s*\|", ln)
        if m:
            names.update(re.findall(r"`(\w+)`", m.group(1)))
    return names


@pytest.mark.parametrize("md", [ROOT / "README.md", DOCS / "scenes.md"], ids=["README.md", "docs/scenes.md"])
def test_scenario_table_is_complete(md):
    """Every scene shipped in scenarios/ has its row in the README's and the scenes page's table."""
    shipped = {p.stem for p in (ROOT / "scenarios").glob("*.toml")}
    missing = sorted(shipped - _scenario_rows(md))
    assert not missing, f"{md.name}: no row for {missing}"


def test_readme_is_the_front_door():
    """README.md stays short and keeps the two set-up commands with their meaning."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= README_MAX_LINES
    assert re.search(r"^make run\s+# creates \.venv, installs, runs scenarios/", text, re.M)
    assert re.search(r"^make test\s+# creates \.venv, installs, runs the test suite", text, re.M)
