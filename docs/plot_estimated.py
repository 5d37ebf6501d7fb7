"""Chart of scenarios/iss_lvlh_hold_estimated.toml: pointing with the truth fed vs with the MEKF's
estimate, and the estimation error against the filter's 3σ (docs/img/iss_lvlh_hold_estimated.png).

Run: ``.venv/bin/python docs/plot_estimated.py`` (needs the ``plot`` extra: matplotlib). One
orbit each; the truth-fed twin is the same scene with ``sensor = []`` and no estimator. Prints
the numbers the README quotes.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import stationbed as sb  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(out=ROOT / "docs" / "img" / "iss_lvlh_hold_estimated.png"):
    est = sb.load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml").replace({"simulation.output_dt": 2.0})
    truth = est.replace({"sensor": [], "estimator": None})
    te, tt = sb.simulate(est), sb.simulate(truth)
    c = te.columns.index
    t = te.t / 60.0
    fig, ax = plt.subplots(5, 1, figsize=(9, 12), sharex=True)
    ax[0].semilogy(tt.t / 60, tt.data[:, tt.columns.index("att_err_deg")], label="truth fed")
    ax[0].semilogy(t, te.data[:, c("att_err_deg")], label="MEKF estimate fed", alpha=0.8)
    ax[0].set_ylabel("pointing error\nfrom LVLH [deg]")
    ax[0].legend()
    ax[0].set_title("iss_lvlh_hold_estimated: pd on the truth vs on the MEKF (2 gyros, 2 star-tracker heads)")
    for i, a in enumerate("xyz"):
        e, s3 = te.data[:, c(f"est_err_{a}_deg")] * 3600, te.data[:, c(f"est_3sigma_{a}_deg")] * 3600
        ax[1 + i].plot(t, e, lw=0.8, label=f"estimation error {a} (truth vs estimate)")
        ax[1 + i].plot(t, s3, "k--", lw=0.8, label="filter 3σ")
        ax[1 + i].plot(t, -s3, "k--", lw=0.8)
        ax[1 + i].set_ylim(-8 * np.median(s3), 8 * np.median(s3))
        ax[1 + i].set_ylabel(f"{a} [arcsec]")
        ax[1 + i].legend(loc="upper right", fontsize=8)
    for h in ("st1", "st2"):
        ax[4].plot(t, te.data[:, c(f"st_valid_{h}")] + (0.02 if h == "st2" else 0.0), label=f"{h} valid")
    ax[4].plot(t, te.data[:, c("nees")] / 6 / 3, lw=0.6, label="NEES / 18", alpha=0.7)
    ax[4].set_ylabel("head valid (0/1)")
    ax[4].set_xlabel("t [min]")
    ax[4].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    se, st = te.meta["summary"], tt.meta["summary"]
    for k in ("max_att_err_deg", "final_att_err_deg", "max_h_fraction"):
        print(f"{k}: truth fed {st[k]:.4g}, estimated {se[k]:.4g}")
    for k in ("est_converged_s", "max_est_err_deg", "rms_est_err_deg", "mean_nees", "est_inside_3sigma", "st_dropout_s"):
        print(f"{k}: {se[k]:.4g}")
    print("wrote", out)


if __name__ == "__main__":
    main()
