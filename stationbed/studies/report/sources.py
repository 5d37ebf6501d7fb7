"""Reports of what stationbed made: a Monte Carlo study folder (:func:`study_report`), a
``stationbed check`` (:func:`check_record`, :func:`check_report`) and a run folder
(:func:`run_report`). Each reads the files the command wrote (``summary.json``, ``study.json``,
``samples.parquet``, the charts; ``check.json``; a run's ``summary.json`` and dashboard), so
``stationbed report DIR`` makes the same report again from a finished folder."""

from __future__ import annotations

import json
import math
import shlex
from pathlib import Path

from ...scene import SceneError
from .model import Case, Report, Table, png_data_uri

__all__ = ["study_report", "check_record", "check_report", "run_report", "WORST_SHOWN", "replay_command",
           "check_command"]

#: the worst samples a report lists per requirement (the first is the failure's "worst sample")
WORST_SHOWN = 3
#: the study's charts shown inline, in this order (those the folder holds): the envelopes first
STUDY_CHARTS = ("envelope_att_err.png", "envelope_h.png")


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise SceneError(f"{path}: missing") from None
    except (OSError, ValueError, UnicodeDecodeError) as e:
        raise SceneError(f"{path}: unreadable ({type(e).__name__}: {e})") from None
    if not isinstance(data, dict):
        raise SceneError(f"{path}: not a JSON object")
    return data


def _g(v) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.6g}"


def _utc(prov: dict, path: Path) -> str:
    """ISO 8601 without a zone (the JUnit schema's timestamp): the provenance's, else the file's."""
    if prov.get("utc"):
        return str(prov["utc"]).rstrip("Z")
    import datetime  # noqa: PLC0415

    return datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")


# -- Monte Carlo ----------------------------------------------------------------------------------
def replay_command(invocation: dict | None, k: int) -> str:
    """The command that runs sample ``k`` alone (``stationbed montecarlo SCENE --sample K``, with
    the study's ``--n`` and ``--set``), its metrics those of the study's row bit for bit."""
    if not invocation:
        return f"stationbed montecarlo SCENE.toml --sample {k}  # SCENE.toml: the study's scene file"
    cmd = ["stationbed", "montecarlo", str(invocation["scene_file"]), "--n", str(invocation["n"]), "--sample", str(k)]
    for s in invocation.get("set", []):
        cmd += ["--set", s]
    return shlex.join(cmd)


def _worst(df, r: dict):
    """The rows of ``df`` worst for requirement ``r``: samples that did not run first, then by
    the metric's value beyond the limit (largest for a max, smallest for a min)."""
    m = r["metric"]
    if df is None or m not in df:
        return []
    ran = df["status"] == "ok"
    v = df[m].astype(float)
    key = -v if r["bound"] == "max" else v
    order = df.assign(_ran=ran & v.notna(), _key=key).sort_values(["_ran", "_key", "index"], kind="stable")
    return [row for _, row in order.head(WORST_SHOWN).iterrows()]


def _meets(r: dict, row) -> bool:
    v = float(row[r["metric"]])
    if row["status"] != "ok" or math.isnan(v):
        return False
    return v <= r["limit"] if r["bound"] == "max" else v >= r["limit"]


def _requirement_name(r: dict) -> str:
    op = "<=" if r["bound"] == "max" else ">="
    return (f"{r['metric']} {op} {r['limit']:g} in {100 * r['coverage']:g} % of cases at "
            f"{100 * r['confidence']:g} % confidence")


def _sample_words(r: dict, row, drawn: list[str]) -> str:
    v = row[r["metric"]]
    words = f"sample {int(row['index'])}: {r['metric']} = {_g(float(v))} (limit {r['limit']:g})"
    if row["status"] != "ok":
        words += f"; {row['status']}: {row.get('reason', '')}"
    vals = ", ".join(f"{c} = {row[c]:.6g}" if isinstance(row[c], float) else f"{c} = {row[c]}" for c in drawn)
    return words + (f"; drawn {vals}" if vals else "")


def study_report(folder: Path) -> Report:
    """The report of a finished Monte Carlo study in ``folder`` (summary.json, study.json,
    samples.parquet, the charts): one case per requirement; a failed one's details name the
    worst samples, their numbers and the command that replays each."""
    from ..montecarlo.report import drawn_of, table_text  # noqa: PLC0415
    from ..montecarlo.stats import NOT_SHOWN, PASS  # noqa: PLC0415

    folder = Path(folder)
    summary = _read_json(folder / "summary.json")
    record = _read_json(folder / "study.json") if (folder / "study.json").exists() else {}
    df = None
    if (folder / "samples.parquet").exists():
        import pandas as pd  # noqa: PLC0415

        df = pd.read_parquet(folder / "samples.parquet")
    drawn = drawn_of(df) if df is not None else []
    inv = record.get("invocation")
    scene = summary["scene"]
    cases, worst_rows, worst_bad = [], [], []
    for r in summary.get("requirements", []):
        worst = _worst(df, r)
        lines = [f"{r['failures']} of {r['n']} samples fail ({r['not_run']} did not run to the end); "
                 f"success lower bound {r['success_lower_bound']:.4f} at {100 * r['confidence']:g} % confidence "
                 f"(coverage asked {r['coverage']:g}); 0 failures need n >= {r['n_needed_zero_failures']}"]
        for row in worst:
            k = int(row["index"])
            lines += [("worst " if row is worst[0] else "next ") + _sample_words(r, row, drawn),
                      f"  replay: {replay_command(inv, k)}"]
            worst_rows.append([r.get("id") or r["metric"], str(k), str(row["status"]), _g(float(row[r["metric"]])),
                               f"{'<=' if r['bound'] == 'max' else '>='} {r['limit']:g}",
                               str(row.get("reason", "") or ""), replay_command(inv, k)])
            worst_bad.append(not _meets(r, row))
        word = r["verdict"]
        message = r.get("note", f"{r['failures']} of {r['n']} fail")
        if word != PASS and worst and word != NOT_SHOWN:
            message += f"; worst: {_sample_words(r, worst[0], [])}"
        name = (f"{r['id']}: " if r.get("id") else "") + _requirement_name(r)
        cases.append(Case(suite=f"montecarlo.{scene}", name=name, verdict=word, passed=word == PASS,
                          message=message, details="\n".join(lines), id=r.get("id"), text=r.get("text"),
                          numbers=f"{r['failures']}/{r['n']} fail; lower bound {r['success_lower_bound']:.4f} "
                                  f"(>= {r['coverage']:g} to pass)"))
    tables = []
    if worst_rows:
        tables.append(Table("Worst samples", ["requirement", "sample", "status", "value", "limit", "reason",
                                              "replay (the sample alone, its metrics bit for bit)"],
                            worst_rows, worst_bad, code_column=6,
                            note=f"The {WORST_SHOWN} worst samples per requirement; each command writes the "
                                 "sample's scene file and runs it alone (its metrics equal the row's bit for bit)."))
    metrics = summary.get("metrics", {})
    if metrics:
        tables.append(Table("Metrics over the samples that ran",
                            ["metric", "unit", "count", "mean", "std", "p50", "p99.73", "max", "at sample"],
                            [[m, s.get("unit", ""), str(s["count"]), _g(s["mean"]), _g(s.get("std")), _g(s.get("p50")),
                              _g(s.get("p99.73")), _g(s["max"]), str(s["max_index"])] for m, s in metrics.items()],
                            note="Blank (-) percentiles: too few samples to support them (summary.json "
                                 "percentile_needs_n)."))
    wanted = list(STUDY_CHARTS) + [f"{kind}_{r['metric']}.png" for r in summary.get("requirements", [])
                                   for kind in ("hist", "scatter")]
    charts = [(name, png_data_uri(folder / name)) for name in dict.fromkeys(wanted) if (folder / name).is_file()]
    prov = dict(record.get("provenance", {}))
    provenance = {"scene": scene, "scene_sha256": record.get("scene_sha256", "-"), "study": record.get("study", "-"),
                  "seed": summary.get("seed"), "n": summary.get("n"), **prov,
                  "workers": summary.get("workers"), "wall_s": _g(summary.get("wall_s"))}
    if inv:
        provenance["command"] = shlex.join(["stationbed", "montecarlo", str(inv["scene_file"]), "--n", str(inv["n"]),
                                            *[a for s in inv.get("set", []) for a in ("--set", s)]])
    return Report(title=f"Monte Carlo: {scene}", kind="montecarlo", suite=f"montecarlo.{scene}", cases=cases,
                  tables=tables, charts=charts, lines=table_text(summary).splitlines(), provenance=provenance,
                  time_s=float(summary.get("wall_s") or 0.0), utc=_utc(prov, folder / "summary.json"))


# -- stationbed check -----------------------------------------------------------------------------
def check_command(args) -> str:
    """The ``stationbed check`` command line ``args`` (argparse) stands for."""
    cmd = ["stationbed", "check", str(args.scene)]
    for flag in ("integrator", "rtol", "atol", "duration", "output_dt"):
        v = getattr(args, flag, None)
        if v is not None:
            cmd += [f"--{flag.replace('_', '-')}", str(v)]
    for s in getattr(args, "set", []):
        cmd += ["--set", s]
    return shlex.join(cmd)


def check_record(res, scene, command: str = "", wall_s: float = 0.0) -> dict:
    """``check.json``: the pairs' differences, the tolerances, the scene hash and the provenance
    of a :class:`~stationbed.studies.check.CheckResult`."""
    import hashlib  # noqa: PLC0415

    from ...core.provenance import provenance  # noqa: PLC0415

    data = scene.model_dump(mode="json")
    return {"scene": res.scene, "scene_sha256": hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest(),
            "command": command, "rtol": res.rtol, "wall_s": wall_s,
            "tolerance": {"att_rad": res.tol_att_rad, "rate_rad_s": res.tol_rate, "H_Nms": res.tol_H,
                          "eta": res.tol_eta},
            "pairs": [{"a": p.a, "b": p.b, "att_rad": p.att_rad, "rate_rad_s": p.rate, "H_Nms": p.H, "eta": p.eta,
                       "ok": res.pair_ok(p)} for p in res.pairs],
            "ok": res.ok, "provenance": provenance()}


#: check.json's quantities: key, what it is, unit
CHECK_QUANTITIES = (("att_rad", "attitude", "rad"), ("rate_rad_s", "rate", "rad/s"), ("H_Nms", "H_O_N", "N m s"),
                    ("eta", "modes eta", ""))


def check_report(rec: dict) -> Report:
    """The report of a ``stationbed check`` (its ``check.json``): one case per scene x
    formulation pair; a failed one names each quantity beyond its tolerance."""
    scene, tol = rec["scene"], rec["tolerance"]
    cases = []
    for p in rec["pairs"]:
        q = [(name, p[k], tol[k], unit) for k, name, unit in CHECK_QUANTITIES if p.get(k) is not None]
        beyond = [f"{name} {v:.3e} {unit} > tolerance {t:.3e}".rstrip() for name, v, t, unit in q if v > t]
        numbers = "; ".join(f"{name} {v:.3e} (tol {t:.3e})" for name, v, t, _ in q)
        details = "\n".join([f"{p['a']} vs {p['b']} on {scene} at rtol {rec['rtol']:g}: {numbers}",
                             f"replay: {rec['command']}" if rec.get("command") else ""]).strip()
        cases.append(Case(suite=f"check.{scene}", name=f"{p['a']} vs {p['b']}", verdict="ok" if p["ok"] else "DISAGREE",
                          passed=bool(p["ok"]), message="; ".join(beyond) or "within tolerance", details=details,
                          numbers=numbers))
    prov = dict(rec.get("provenance", {}))
    provenance = {"scene": scene, "scene_sha256": rec.get("scene_sha256", "-"), "rtol": rec["rtol"], **prov}
    if rec.get("command"):
        provenance["command"] = rec["command"]
    lines = [f"scene {scene}: {len(rec['pairs'])} formulation pairs at rtol {rec['rtol']:g}, tolerances: "
             + ", ".join(f"{name} {tol[k]:.3e} {unit}".rstrip() for k, name, unit in CHECK_QUANTITIES
                         if tol.get(k) is not None)]
    return Report(title=f"Cross-formulation check: {scene}", kind="check", suite=f"check.{scene}", cases=cases,
                  lines=lines, provenance=provenance, time_s=float(rec.get("wall_s") or 0.0),
                  utc=_utc(prov, Path(".")))


# -- a run folder ---------------------------------------------------------------------------------
def run_report(folder: Path) -> Report:
    """The report of a run folder (``stationbed run``): one case, the run (failed or interrupted:
    a failure with its reason), its closed-loop summary and its dashboard (drawn when missing)."""
    folder = Path(folder)
    meta = _read_json(folder / "summary.json")
    name = str(meta.get("scene", folder.name))
    status = str(meta.get("status", "unknown"))
    ok = status == "ok"
    at = meta.get("stopped_at", meta.get("last_t"))
    why = "" if ok else (f"the run {status}" + (f" at t = {at:g} s" if isinstance(at, (int, float)) else "")
                         + (f": {meta['reason']}" if meta.get("reason") else "")
                         + f"; {meta.get('n_rows', meta.get('rows', '?'))} rows kept in {meta.get('rows_file', '-')}")
    loop = meta.get("summary") or {}
    rows = [[k, _g(v) if isinstance(v, float) else str(v)] for k, v in loop.items()
            if isinstance(v, (int, float, str)) and not isinstance(v, bool)]
    tables = [Table("Closed-loop summary", ["quantity", "value"], rows)] if rows else []
    charts = []
    png = folder / "dashboard.png"
    if not png.is_file():
        try:
            from ...analysis.dashboard import dashboard  # noqa: PLC0415

            dashboard(folder)
        except (ValueError, OSError, ImportError):  # no rows, no matplotlib: a report without it
            pass
    if png.is_file():
        charts.append(("dashboard.png", png_data_uri(png)))
    keep = ("scene", "formulation", "integrator", "rtol", "atol", "evaluator", "n_rows", "n_rhs", "rows_file")
    provenance = {k: meta[k] for k in keep if k in meta}
    case = Case(suite=f"run.{name}", name=f"run {name}", verdict=status, passed=ok,
                message=why or f"{meta.get('n_rows', '?')} rows", details=str(why),
                numbers=f"{meta.get('n_rows', '?')} rows, {meta.get('n_rhs', '?')} RHS evaluations")
    return Report(title=f"Run: {name}", kind="run", suite=f"run.{name}", cases=[case], tables=tables, charts=charts,
                  provenance=provenance, time_s=float(meta.get("wall_s") or 0.0),
                  utc=_utc({}, folder / "summary.json"))
