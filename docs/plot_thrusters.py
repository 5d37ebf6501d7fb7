"""Chart of scenarios/iss_cmg_thruster_assist.toml: |h| with the thruster firings, against the
bare PD hold (the same scene without thrusters), with the cumulative propellant and the attitude
error (docs/img/iss_cmg_thruster_assist.png).

Run: ``.venv/bin/python docs/plot_thrusters.py`` (needs the ``plot`` extra: matplotlib). Three
orbits each (the scene's duration). Prints the numbers the README quotes.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import stationbed as sb  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(out=ROOT / "docs" / "img" / "iss_cmg_thruster_assist.png"):
    thr = sb.load_scene(ROOT / "scenarios" / "iss_cmg_thruster_assist.toml")
    bare = thr.replace({"thruster": [], "thrusters": None})
    ta, tb = sb.simulate(thr), sb.simulate(bare)
    sa, sbm = ta.meta["summary"], tb.meta["summary"]
    cap = sa["h_capacity_Nms"]
    c = ta.columns.index
    t = ta.t / 60.0
    h_a = np.linalg.norm(ta.data[:, [c("hx"), c("hy"), c("hz")]], axis=1) / cap
    cb = tb.columns.index
    h_b = np.linalg.norm(tb.data[:, [cb("hx"), cb("hy"), cb("hz")]], axis=1) / cap
    fired = np.flatnonzero(np.diff(ta.data[:, c("thr_firings")]) > 0) + 1  # rows after a firing
    dumping = ta.data[:, c("thr_dumping")] > 0.5
    o = thr.thrusters
    fig, ax = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
    ax[0].plot(tb.t / 60, h_b, label="bare PD (no thrusters)", color="0.5")
    ax[0].plot(t, h_a, label="CMG thruster assist")
    ax[0].fill_between(t, 0, 1, where=dumping, color="tab:orange", alpha=0.15, transform=ax[0].get_xaxis_transform(),
                       label="dumping")
    ax[0].plot(t[fired], h_a[fired], "|", color="tab:red", ms=10, label="rows with a firing")
    for v, name in ((o.assist_on, "assist_on"), (o.dump_stop, "dump_stop"), (o.h_min, "h_min")):
        ax[0].axhline(v, ls=":", color="k", lw=0.8)
        ax[0].text(t[-1], v, f" {name}", va="center", fontsize=8)
    ax[0].set_ylabel("|h| / capacity")
    ax[0].legend(loc="upper left", fontsize=8)
    ax[0].set_title(f"{thr.name}: 16 thrusters (130 N, Isp 280 s), 4 DGCMGs, 3 orbits")
    ax[1].plot(t, ta.data[:, c("thr_propellant_kg")])
    ax[1].set_ylabel("propellant [kg]")
    ax[2].semilogy(tb.t / 60, tb.data[:, cb("att_err_deg")], color="0.5", label="bare PD")
    ax[2].semilogy(t, ta.data[:, c("att_err_deg")], label="CMG thruster assist", alpha=0.8)
    ax[2].set_ylabel("attitude error\nfrom LVLH [deg]")
    ax[2].set_xlabel("time [min]")
    ax[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    for name, s in (("bare PD", sbm), ("CMG thruster assist", sa)):
        print(f"{name}: max |h| {s['max_h_fraction']:.3f} of capacity, max att err {s['max_att_err_deg']:.3g} deg, "
              f"RMS {s['rms_att_err_deg']:.3g} deg, propellant {s.get('propellant_kg', 0.0):.4g} kg "
              f"({s.get('propellant_kg_per_orbit', 0.0):.4g} kg/orbit), firings {s.get('thruster_firings', 0)}, "
              f"rate-limited ticks {s['rate_limited_ticks']}")


if __name__ == "__main__":
    main()
