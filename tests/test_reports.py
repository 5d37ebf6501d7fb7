"""Reports (issue 37 item 1): JUnit XML and the self-contained HTML report of a Monte Carlo
study, a ``stationbed check`` and a run.

Truths:
- the JUnit XML is valid against the Apache Ant JUnit schema that CI servers read
  (tests/data/junit/JUnit.xsd, validated with lxml), and its failures are the requirements the
  samples table (samples.parquet, read here with pandas) shows failed: the worst sample named
  in a failure is the table's largest value of the metric;
- the replay command printed for the worst sample, run as printed, gives that sample's metric
  bit for bit;
- the HTML opens in headless Chromium (the browser ``stationbed screenshot`` drives) with its
  verdict table rendered (DOM query on the dumped DOM), the failed requirement's verdict cell
  painted red (the browser's computed style), and nothing fetched: no resource timing entry,
  every src/href a data: URI or a fragment;
- ``stationbed report DIR`` writes the same files again from the finished folder;
- a formulation pair beyond a tolerance is a failed case of the check's report, and a failed
  run is a failed case of the run's report.
"""

import dataclasses
import json
import re
import shlex
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest

from scenes import ROOT
from stationbed import load_scene
from stationbed.cli import main
from stationbed.output.rerun.screenshot import find_browser
from stationbed.scene import SceneError
from stationbed.studies.check import check_scene
from stationbed.studies.montecarlo.folder import study_identity
from stationbed.studies.report import check_record, check_report
from stationbed.studies.report.junit import junit_xml

lxml_etree = pytest.importorskip("lxml.etree")

MC_SCENE = ROOT / "scenarios" / "iss_lvlh_hold_montecarlo.toml"
JUNIT_XSD = ROOT / "tests" / "data" / "junit" / "JUnit.xsd"
#: the longest the browser may take to open and dump one report [s] (a bound, never reached when fine)
BROWSER_TIMEOUT_S = 120
#: a computed colour is "red" when its red channel is at least this and green and blue at most
#: RED_OTHERS_MAX (the failed verdict's background is #d00020: 208, 0, 32)
RED_MIN, RED_OTHERS_MAX = 150, 80

#: three requirements on 2 samples of 60 s: one every sample fails (FAIL), one shown with
#: coverage and confidence 0.5 (a single passing sample shows it: n >= ln 0.5 / ln 0.5 = 1), one
#: at the default 99.73 % / 90 % that 2 samples cannot show (NOT SHOWN)
REQUIREMENTS = '''
[[montecarlo.requirement]]
metric = "max_att_err_deg"
id = "SB-ATT-1"
text = "The attitude error shall stay within 0.001 deg of LVLH."
max = 0.001

[[montecarlo.requirement]]
metric = "max_h_fraction"
id = "SB-CMG-2"
max = 0.9
coverage = 0.5
confidence = 0.5

[[montecarlo.requirement]]
metric = "max_h_fraction"
max = 0.9
'''


def study_text(n=2, requirements=REQUIREMENTS) -> str:
    text = MC_SCENE.read_text().replace("duration = 5553.6", "duration = 60.0")
    text = text.replace("settle_s = 1800.0", "settle_s = 20.0").replace("envelope_dt = 30.0", "envelope_dt = 20.0")
    text = text.replace("n = 1000", f"n = {n}")
    return text[:text.index("[[montecarlo.requirement]]")] + requirements


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A finished study (charts on) whose first requirement fails: its folder and exit status."""
    base = tmp_path_factory.mktemp("reports")
    scene = base / "scene.toml"
    scene.write_text(study_text())
    out = base / "mc"
    code = main(["montecarlo", str(scene), "--serial", "--out", str(out), "-q"])
    return out, code


def junit_cases(path: Path) -> dict[str, ET.Element]:
    return {c.get("name"): c for c in ET.parse(path).getroot().iter("testcase")}


def assert_valid_junit(path: Path) -> None:
    schema = lxml_etree.XMLSchema(lxml_etree.parse(str(JUNIT_XSD)))
    doc = lxml_etree.parse(str(path))
    assert schema.validate(doc), str(schema.error_log)


# -- Monte Carlo: JUnit XML -----------------------------------------------------------------------
def test_study_exit_status_is_unchanged_by_the_reports(study):
    out, code = study
    assert code == 1  # a requirement FAILed (and one is NOT SHOWN)
    assert (out / "junit.xml").is_file() and (out / "report.html").is_file()


def test_study_junit_is_valid_against_the_ant_schema(study):
    assert_valid_junit(study[0] / "junit.xml")


def test_a_failing_requirement_is_a_failed_test_case_naming_its_worst_sample(study):
    out, _ = study
    df = pd.read_parquet(out / "samples.parquet")
    cases = junit_cases(out / "junit.xml")
    assert len(cases) == 3
    failed = {name: c.find("failure") for name, c in cases.items() if c.find("failure") is not None}
    att = next(n for n in cases if n.startswith("SB-ATT-1: max_att_err_deg <= 0.001"))
    shown = next(n for n in cases if n.startswith("SB-CMG-2: "))
    assert set(failed) == {att, next(n for n in cases if n not in (att, shown))}
    assert failed[att].get("type") == "stationbed.FAIL"
    worst = int(df.loc[df["max_att_err_deg"].idxmax(), "index"])
    value = df["max_att_err_deg"].max()
    assert f"worst: sample {worst}: max_att_err_deg = {value:.6g}" in failed[att].get("message")
    assert f"worst sample {worst}: max_att_err_deg = {value:.6g} (limit 0.001)" in failed[att].text
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures")) == ("3", "2")


def test_the_replay_command_gives_the_worst_samples_metric_bit_for_bit(study, tmp_path):
    out, _ = study
    df = pd.read_parquet(out / "samples.parquet")
    case = next(c for n, c in junit_cases(out / "junit.xml").items() if n.startswith("SB-ATT-1"))
    command = re.search(r"^worst sample.*\n  replay: (.*)$", case.find("failure").text, re.M).group(1)
    argv = shlex.split(command)
    assert argv[:2] == ["stationbed", "montecarlo"]
    k = int(argv[argv.index("--sample") + 1])
    assert main([*argv[1:], "--out", str(tmp_path / "replay"), "-q"]) == 0
    got = json.loads((tmp_path / "replay" / "summary.json").read_text())["metrics"]["max_att_err_deg"]
    assert got == df.loc[df["index"] == k, "max_att_err_deg"].item()


def test_report_dir_writes_the_same_files_again(study, tmp_path):
    out, _ = study
    before = {n: (out / n).read_bytes() for n in ("junit.xml", "report.html")}
    for n in before:
        (out / n).unlink()
    assert main(["report", str(out)]) == 0
    assert {n: (out / n).read_bytes() for n in before} == before


# -- Monte Carlo: HTML in headless Chromium -------------------------------------------------------
#: appended to a copy of the report: the browser's computed colour of each verdict cell and the
#: resources the page fetched (resource timing), written into the DOM that --dump-dom prints
PROBE = """<script>
window.addEventListener('load', () => {
  for (const tr of document.querySelectorAll('#verdicts tbody tr'))
    tr.dataset.bg = getComputedStyle(tr.querySelector('td.verdict')).backgroundColor;
  document.body.dataset.resources = JSON.stringify(performance.getEntriesByType('resource').map(e => e.name));
});
</script>"""


def dumped_dom(html: Path, tmp_path: Path):
    """The report as headless Chromium renders it (``--dump-dom`` of a probed copy), parsed by lxml."""
    probe = tmp_path / "probe.html"
    probe.write_text(html.read_text().replace("</body>", PROBE + "</body>"))
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--no-first-run",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}"]
    res = subprocess.run([find_browser(), *flags, "--dump-dom", probe.as_uri()], capture_output=True, text=True,
                         timeout=BROWSER_TIMEOUT_S)
    assert res.returncode == 0, res.stderr[-2000:]
    import lxml.html

    return lxml.html.fromstring(res.stdout)


def rgb(css: str) -> tuple[int, ...]:
    return tuple(int(v) for v in re.findall(r"\d+", css)[:3])


@pytest.mark.skipif(find_browser() is None, reason="no Chromium installed (apt-get install chromium; make screenshots)")
def test_html_verdict_table_renders_with_the_failed_requirement_in_red(study, tmp_path):
    dom = dumped_dom(study[0] / "report.html", tmp_path)
    rows = dom.xpath("//table[@id='verdicts']/tbody/tr")
    by_verdict = {r.get("data-verdict"): r for r in rows}
    assert len(rows) == 3 and set(by_verdict) == {"FAIL", "PASS", "NOT SHOWN"}
    fail = by_verdict["FAIL"]
    assert "fail" in fail.get("class").split() and fail.get("data-id") == "SB-ATT-1"
    assert "The attitude error shall stay within 0.001 deg of LVLH." in fail.text_content()
    r, g, b = rgb(fail.get("data-bg"))
    assert r >= RED_MIN and g <= RED_OTHERS_MAX and b <= RED_OTHERS_MAX, fail.get("data-bg")
    r, g, b = rgb(by_verdict["PASS"].get("data-bg"))
    assert g > r and g > b  # green
    assert "notshown" in by_verdict["NOT SHOWN"].get("class").split()


@pytest.mark.skipif(find_browser() is None, reason="no Chromium installed (apt-get install chromium; make screenshots)")
def test_html_fetches_nothing_and_holds_its_charts_inline(study, tmp_path):
    dom = dumped_dom(study[0] / "report.html", tmp_path)
    assert json.loads(dom.xpath("//body")[0].get("data-resources")) == []
    links = [v for e in dom.iter() if isinstance(e.tag, str)
             for k, v in e.attrib.items() if k in ("src", "href", "srcset", "poster", "data", "action")]
    assert links and all(v.startswith(("data:", "#")) for v in links), links
    assert not dom.xpath("//link | //script[@src] | //iframe | //object | //embed")
    images = {i.get("alt"): i.get("src") for i in dom.xpath("//img")}
    assert {"envelope_att_err.png", "envelope_h.png"} <= set(images)
    assert all(src.startswith("data:image/png;base64,") for src in images.values())


def test_html_lists_the_worst_samples_and_the_provenance(study):
    out, _ = study
    import lxml.html

    dom = lxml.html.fromstring((out / "report.html").read_text())
    record = json.loads((out / "study.json").read_text())
    prov = {r.xpath("th")[0].text_content(): r.xpath("td")[0].text_content()
            for r in dom.xpath("//table[@id='provenance']//tr")}
    assert prov["scene_sha256"] == record["scene_sha256"] and prov["seed"] == "2026"
    assert {"version", "machine", "python"} <= set(prov)
    commands = [c.text_content() for c in dom.xpath("//code")]
    assert commands and all(c.startswith("stationbed montecarlo ") and "--sample" in c for c in commands)


# -- requirement id and text ----------------------------------------------------------------------
def test_requirement_id_and_text_change_no_study_identity():
    plain = load_scene(MC_SCENE)
    named = plain.replace({"montecarlo.requirement": [
        {**r.model_dump(exclude_none=True), "id": f"R{i}", "text": "worded"}
        for i, r in enumerate(plain.montecarlo.requirement)]})
    assert named.montecarlo.requirement[0].id == "R0"
    assert study_identity(named)[0] == study_identity(plain)[0]


def test_a_misspelt_requirement_key_is_refused(tmp_path):
    p = tmp_path / "scene.toml"
    p.write_text(study_text(requirements='[[montecarlo.requirement]]\nmetric = "max_att_err_deg"\nmax = 1.0\n'
                                         'txt = "words"\n'))
    with pytest.raises(SceneError, match=r"montecarlo\.requirement.*txt"):
        load_scene(p)


# -- stationbed check -----------------------------------------------------------------------------
def test_check_out_writes_one_passing_case_per_formulation_pair(tmp_path):
    scene = ROOT / "scenarios" / "power_tower_free_drift.toml"
    assert main(["check", str(scene), "--duration", "20", "--out", str(tmp_path), "-q"]) == 0
    assert_valid_junit(tmp_path / "junit.xml")
    cases = junit_cases(tmp_path / "junit.xml")
    n_forms = len(json.loads((tmp_path / "check.json").read_text())["pairs"])
    assert len(cases) == n_forms == 6  # 4 formulations: 6 pairs
    assert all(c.find("failure") is None for c in cases.values())
    assert all(c.get("classname") == "check.power_tower_free_drift" for c in cases.values())


def test_a_pair_beyond_its_tolerance_is_a_failed_case(tmp_path):
    scene = load_scene(ROOT / "scenarios" / "power_tower_free_drift.toml").replace({"simulation.duration": 20.0})
    res = check_scene(scene)
    att = sorted(p.att_rad for p in res.pairs)
    tight = dataclasses.replace(res, tol_att_rad=(att[0] + att[-1]) / 2)  # between the closest pair and the farthest
    beyond = {f"{p.a} vs {p.b}" for p in res.pairs if p.att_rad > tight.tol_att_rad}
    assert beyond and len(beyond) < len(res.pairs)
    path = tmp_path / "junit.xml"
    path.write_bytes(junit_xml(check_report(check_record(tight, scene))))
    assert_valid_junit(path)
    failed = {n for n, c in junit_cases(path).items() if c.find("failure") is not None}
    assert failed == beyond


# -- a run folder ---------------------------------------------------------------------------------
def test_report_of_a_failed_run_is_a_failed_case(tmp_path):
    out = tmp_path / "run"
    code = main(["run", str(MC_SCENE), "--duration", "20", "--set", "atmosphere.density_scale=1e300",
                 "--out", str(out), "-q"])
    assert code == 1
    assert main(["report", str(out)]) == 0
    assert_valid_junit(out / "junit.xml")
    stopped = json.loads((out / "summary.json").read_text())["stopped_at"]
    (case,) = junit_cases(out / "junit.xml").values()
    assert case.find("failure").get("message").startswith(f"the run failed at t = {stopped:g} s")


def test_report_of_a_finished_run_passes_and_shows_its_dashboard(tmp_path):
    out = tmp_path / "run"
    assert main(["run", str(ROOT / "scenarios" / "power_tower_free_drift.toml"), "--duration", "20",
                 "--out", str(out), "-q"]) == 0
    assert main(["report", str(out)]) == 0
    (case,) = junit_cases(out / "junit.xml").values()
    assert case.find("failure") is None
    assert '<img src="data:image/png;base64,' in (out / "report.html").read_text()


def test_report_of_a_folder_that_holds_no_result_is_bad_input(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "neither a Monte Carlo study" in capsys.readouterr().err
