"""Chart of scenarios/iss_progress_docking.toml and iss_progress_undocking.toml: the attitude
error, the pitch rate and the CMG momentum through the docking and the undocking, with the law
told 60 s after each event and never told (docs/img/iss_progress_docking.png).

Run: ``.venv/bin/python docs/plot_docking.py`` (needs the ``plot`` extra: matplotlib). Prints
the numbers docs/docking.md quotes.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import stationbed as sb  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _runs(name):
    scene = sb.load_scene(ROOT / "scenarios" / f"{name}.toml")
    return {"told after 60 s": sb.simulate(scene),
            "never told": sb.simulate(scene.replace({"event[0].update_after_s": "never"}))}


def main(out=ROOT / "docs" / "img" / "iss_progress_docking.png"):
    fig, ax = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
    for j, name in enumerate(("iss_progress_docking", "iss_progress_undocking")):
        for label, tr in _runs(name).items():
            s = tr.meta["summary"]
            t = tr.t / 60.0
            h = np.linalg.norm(tr.cols("hx", "hy", "hz"), axis=1) / s["h_capacity_Nms"]
            ax[0, j].plot(t, tr["att_err_deg"], label=label)
            ax[1, j].plot(t, tr["wy"] * 1e3, label=label)
            ax[2, j].plot(t, 100 * h, label=label)
            after = tr.t >= 600.0
            print(f"{name} ({label}): max attitude error after the event {tr['att_err_deg'][after].max():.3f} deg, "
                  f"final {tr['att_err_deg'][-1]:.3f} deg; max |h| {100 * h.max():.0f} % (at the event "
                  f"{100 * h[np.searchsorted(tr.t, 600.0)]:.0f} %); fused {s['fused']}")
        for a in ax[:, j]:
            a.axvline(10.0, color="0.6", ls=":")
            a.axvline(11.0, color="0.8", ls=":")
        ax[0, j].set_title(name.replace("iss_progress_", "Progress ").replace("_", " ") + " at 10 min (law told at 11)")
    ax[0, 0].set_ylabel("attitude error [deg]")
    ax[1, 0].set_ylabel("pitch rate ω_y [mrad/s]")
    ax[2, 0].set_ylabel("CMG |h| [% of capacity]")
    for a in ax[2]:
        a.set_xlabel("time [min]")
    ax[0, 0].legend()
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
