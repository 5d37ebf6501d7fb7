"""Chart of scenarios/flexible_array_slew.toml: body slew and array bending (docs/img/flexible_array_slew.png).

Run: ``.venv/bin/python docs/plot_flexible_slew.py`` (needs the ``plot`` extra: matplotlib).
Also runs the rigid twin (the same scene with the modes removed) to show what the modes change.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import stationbed as sb  # noqa: E402
import numpy as np  # noqa: E402

from stationbed.core.rotation import rotation_angle  # noqa: E402
from stationbed.scene import scene_from_dict  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(out=ROOT / "docs" / "img" / "flexible_array_slew.png"):
    flex = sb.load_scene(ROOT / "scenarios" / "flexible_array_slew.toml")
    tr = sb.simulate(flex)
    data = flex.model_dump()
    for a in data["appendage"]:
        a["mode"] = []
    tr0 = sb.simulate(scene_from_dict(data))
    fig, ax = plt.subplots(3, 1, figsize=(9, 8.5), sharex=True)
    diff = np.rad2deg(rotation_angle(tr.q_BN, tr0.q_BN)) * 3600.0
    ax[0].plot(tr.t, diff, color="C0")
    ax[0].set_ylabel("flexible vs rigid\nattitude [arcsec]")
    ax0b = ax[0].twinx()
    ax0b.plot(tr.t, tr["att_err_deg"], color="0.6", lw=0.8)
    ax0b.set_ylabel("slew error [deg] (grey)", color="0.4")
    labels = {1: "1st out-of-plane, 0.12 Hz", 2: "1st in-plane, 0.3 Hz", 3: "2nd out-of-plane, 0.75 Hz"}
    for k, lab in labels.items():
        ax[1].plot(tr.t, 1e3 * tr[f"eta_stbd_{k}"], lw=0.9, label=lab)
    ax[1].set_ylabel("stbd tip deflection [mm]")
    ax[1].legend(loc="upper right", fontsize=8)
    ax[2].semilogy(tr.t, tr["U_strain"], color="C3")
    ax[2].set_ylabel("strain energy [J]")
    ax[2].set_xlabel("t [s]")
    fig.suptitle("flexible_array_slew: a 90° eigenaxis slew rings the solar arrays")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}; max attitude difference flexible vs rigid {diff.max():.3g} arcsec")


if __name__ == "__main__":
    main()
