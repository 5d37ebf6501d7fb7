"""Chart of scenarios/iss_cmg_failure_fdir.toml (docs/img/iss_cmg_failure_fdir.png): the
attitude transient around the CMG failure with flight software's isolation and without it
(``isolate = false``) and with no failure, the momentum residual's chi-squared against its gate,
the orbit's |h| and mode, and (given a Monte Carlo folder) the detection latency over its samples.

Run: ``.venv/bin/python docs/plot_fdir.py [out/mc_fdir]`` (the ``plot`` extra: matplotlib; the
folder of ``stationbed montecarlo scenarios/iss_cmg_failure_fdir_montecarlo.toml --n 200 --out
out/mc_fdir``). Prints the numbers docs/faults.md quotes.
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.stats import beta, chi2  # noqa: E402

import stationbed as sb  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ZOOM_S = (2380.0, 2520.0)  # s, around the failure at 2400 s


def _mc(folder):
    import pandas as pd  # noqa: PLC0415

    df = pd.read_parquet(Path(folder) / "samples.parquet")
    if "fault.cmg2.occurred" in df:  # the samples the failure occurred in (probability < 1)
        df = df[df["fault.cmg2.occurred"] > 0.5]
    t_f, unit = df["fault.cmg2.t"].to_numpy(float), df["fault.cmg2.unit"].to_numpy(float)  # the truth drawn
    det, blamed = df["fdir_detect_s"].to_numpy(float), df["fdir_unit"].to_numpy(float)
    return t_f, unit, det, blamed


def main(mc=None, out=ROOT / "docs" / "img" / "iss_cmg_failure_fdir.png"):
    scene = sb.load_scene(ROOT / "scenarios" / "iss_cmg_failure_fdir.toml")
    fd = scene.fdir
    zoom = {"simulation.duration": ZOOM_S[1], "simulation.output_dt": 0.5}
    runs = {"FDIR: detected, isolated, assist": sb.simulate(scene.replace(zoom)),
            "detected, not isolated (the same to 6e-4 deg)": sb.simulate(scene.replace({**zoom, "fdir.isolate": False})),
            "no failure": sb.simulate(scene.replace({**zoom, "fault.cmg2.t": ZOOM_S[1]}))}
    full = sb.simulate(scene)
    sm = full.meta["summary"]
    fig, ax = plt.subplots(4 if mc else 3, 1, figsize=(9, 12 if mc else 9.5))
    for (name, tr), color in zip(runs.items(), ("tab:blue", "tab:red", "0.5")):
        keep = tr.t >= ZOOM_S[0]
        ax[0].plot(tr.t[keep], tr["att_err_deg"][keep], label=name, color=color)
    tr = runs["FDIR: detected, isolated, assist"]
    keep = tr.t >= ZOOM_S[0]
    t_f, t_d = sm["fault_cmg_t_s"], sm["fdir_cmg_t_s"]
    for a in ax[:2]:
        a.axvline(t_f, color="k", ls=":", lw=0.8)
        a.axvline(t_d, color="tab:green", ls="--", lw=0.8)
    ax[0].text(t_f, ax[0].get_ylim()[1], " unit 2 fails", va="top", fontsize=8)
    ax[0].text(t_d, ax[0].get_ylim()[1] * 0.9, f" declared (+{t_d - t_f:.1f} s), unit {sm['fdir_cmg_unit']}",
               va="top", fontsize=8, color="tab:green")
    ax[0].set_ylabel("attitude error\nfrom LVLH [deg]")
    ax[0].set_title(f"{scene.name}: a CMG unit fails, flight software notices")
    ax[0].legend(fontsize=8, loc="lower right")
    gate = chi2.isf(fd.cmg_alpha, 3)
    ax[1].semilogy(tr.t[keep], np.maximum(tr["fdir_cmg_nis"][keep], 1e-12), color="tab:blue")
    ax[1].axhline(gate, color="tab:red", lw=0.8)
    ax[1].text(ZOOM_S[0], gate, f" gate (alpha {fd.cmg_alpha:g}, N {fd.cmg_persistence})", va="bottom", fontsize=8)
    ax[1].set_ylabel("momentum residual\nchi-squared")
    ax[1].set_xlabel("time [s]")
    cap = sm["h_capacity_Nms"]
    h = np.linalg.norm(full.cols("hx", "hy", "hz"), axis=1) / cap
    ax[2].plot(full.t / 60, h, label="|h| / capacity (4 units)")
    ax[2].plot(full.t / 60, full["fdir_mode"] / 3, drawstyle="steps-post", label="mode / 3 (0 hold, 1/3 assist)")
    ax[2].plot(full.t / 60, full["thr_propellant_kg"] / max(sm["propellant_kg"], 1e-9) * 0.2, ls=":",
               label=f"propellant (0.2 = {sm['propellant_kg']:.3g} kg)")
    ax[2].axvline(t_f / 60, color="k", ls=":", lw=0.8)
    ax[2].set_xlabel("time [min]")
    ax[2].legend(fontsize=8)
    print(f"detected at {t_d} s (fault {t_f} s, latency {sm['fdir_cmg_latency_s']:.2f} s), unit "
          f"{sm['fdir_cmg_unit']} right {sm['fdir_cmg_unit_right']}; propellant {sm['propellant_kg']:.4g} kg, "
          f"{sm['thruster_firings']} firings; max att err {sm['max_att_err_deg']:.3g} deg")
    for name, r in runs.items():
        s = r.meta["summary"]
        print(f"  {name}: max att err after the failure {r['att_err_deg'][r.t >= t_f].max():.4g} deg, "
              f"final {s['final_att_err_deg']:.4g} deg")
    if mc:
        t_f, unit, det, blamed = _mc(mc)
        ok = det >= 0
        lat = det[ok] - t_f[ok]
        n, k = len(det), int(ok.sum())
        right = int(np.sum(blamed[ok] == unit[ok]))
        lo = beta.ppf(0.025, right, n - right + 1) if right else 0.0
        ax[3].hist(lat, bins=np.arange(-0.05, max(lat.max(), 2.0) + 0.2, 0.1), color="tab:blue")  # a bin per tick
        ax[3].set_xlabel("detection latency [s] (Monte Carlo over failure time and unit)")
        ax[3].set_ylabel("samples")
        ax[3].set_title(f"{k} of {n} detected, {right} blamed the failed unit", fontsize=9)
        print(f"Monte Carlo: {n} samples, {k} detected, {right} right unit (95 % lower bound {lo:.3f}); latency "
              f"min {lat.min():.2f} s, median {np.median(lat):.2f} s, max {lat.max():.2f} s")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
