"""The figure of docs/brdf-fitting.md's measured materials: a goniometer table, interpolated.

As the peer paper's Fig. 4 (``amcw-tof-multipath-simulation-rsm``, Section 5.1): polar plots in
the plane of incidence for one incidence angle, the raw measurements (with the goniometer's
gaps around retro-reflection and beyond 80 deg) and the tabulated material's BRDF, which closes
the gaps by the extended inverse distance weighting (eqs. 16-17). The "measurements" are two
presets sampled as the paper's goniometer would (its 5-deg steps for a diffuse material, 2-deg
for a glossy one), so the analytic truth is drawn too.

Run from the repository root::

    PYTHONPATH=. python docs/plots/brdf_tabulated.py [OUTPUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from sim_core.materials import Tabulated, material_preset
from sim_core.materials.goniometer import GoniometerTable
from sim_core.materials.idw import configuration_directions, goniometer_measurement

#: the incidence angle of the plots [deg] (the paper's Fig. 4: 30 deg)
INCIDENCE_DEG = 30.0
#: the goniometer's blind spots (the paper's Section 4.2) [deg]
RETRO_GAP_DEG = 10.0
MAX_ZENITH_DEG = 80.0
#: (preset, goniometer step [deg], title)
PANELS = (
    ("white-matte-tile", 5.0, "white matte tile (diffuse), 5° steps"),
    ("thermal-control-film", 2.0, "thermal-control film (glossy), 2° steps"),
)
DEFAULT_OUTPUT = Path(__file__).resolve().parents[1] / "images" / "brdf-tabulated.png"


def goniometer_table(preset: str, step_deg: float) -> GoniometerTable:
    """``preset`` sampled on (θi, θr, Δφ) steps, without the goniometer's blind spots."""
    return goniometer_measurement(material_preset(preset), step_deg, retro_gap_deg=RETRO_GAP_DEG,
                                  max_zenith_deg=MAX_ZENITH_DEG, source=preset)


def plane_of_incidence(table: GoniometerTable) -> tuple[np.ndarray, np.ndarray]:
    """Signed viewing angles [deg] (negative: the light's side) and values of the rows measured
    at ``INCIDENCE_DEG`` in the plane of incidence (Δφ = 0 or 180)."""
    at = np.isclose(table.incidence_zenith_deg, INCIDENCE_DEG)
    side = np.isclose(table.azimuth_difference_deg, 0.0) | np.isclose(
        table.azimuth_difference_deg, 180.0)
    sel = at & side
    sign = np.where(np.isclose(table.azimuth_difference_deg[sel], 0.0), -1.0, 1.0)
    return sign * table.reflection_zenith_deg[sel], table.brdf_per_sr[sel]


def curve(material, view_deg: np.ndarray) -> np.ndarray:
    """BRDF in the plane of incidence at ``INCIDENCE_DEG`` for signed viewing angles."""
    wi, wo = configuration_directions(np.full(view_deg.shape, INCIDENCE_DEG), np.abs(view_deg),
                                      np.where(view_deg < 0.0, 0.0, 180.0))
    return material.eval_local(wi, wo)


def plot(output: Path = DEFAULT_OUTPUT) -> Path:
    """Draw the figure into ``output`` (PNG) and return its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, 2, subplot_kw={"projection": "polar"}, figsize=(11.0, 4.6))
    view = np.linspace(-89.5, 89.5, 1433)
    for ax, (preset, step, title) in zip(axes, PANELS, strict=True):
        table = goniometer_table(preset, step)
        mat = Tabulated(table)
        raw_view, raw_f = plane_of_incidence(table)
        # angles measured from the normal (up), the light's side to the left
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)
        ax.set_thetamin(-90.0)
        ax.set_thetamax(90.0)
        ax.plot(np.radians(view), curve(material_preset(preset), view), color="0.6", lw=1.0,
                ls="--", label="analytic model (truth)")
        ax.plot(np.radians(view), curve(mat, view), color="tab:red", lw=1.6,
                label="tabulated (IDW-filled, interpolated)")
        ax.plot(np.radians(raw_view), raw_f, "k.", ms=3.5, label="raw goniometer rows")
        top = 1.1 * max(raw_f.max(), curve(mat, view).max())
        ax.plot([np.radians(-INCIDENCE_DEG)] * 2, [0.0, top], color="tab:blue", lw=1.2,
                label="incident light")
        ax.plot([np.radians(INCIDENCE_DEG)] * 2, [0.0, top], color="tab:red", lw=0.8, ls=":",
                label="mirror direction")
        for lo, hi in ((-INCIDENCE_DEG - RETRO_GAP_DEG, -INCIDENCE_DEG + RETRO_GAP_DEG),
                       (-90.0, -MAX_ZENITH_DEG), (MAX_ZENITH_DEG, 90.0)):
            ax.fill_between(np.radians(np.linspace(lo, hi, 30)), 0.0, top, color="0.85",
                            lw=0, label="goniometer's blind spots" if lo < -85.0 else None)
        ax.set_ylim(0.0, top)
        ax.yaxis.set_major_locator(MaxNLocator(4))
        ax.tick_params(axis="y", labelsize=7)
        ax.text(0.5, 0.82, f"{title}\nθi = {INCIDENCE_DEG:g}°, BRDF [1/sr], plane of incidence",
                transform=ax.transAxes, ha="center", fontsize=9)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.03, right=0.97, top=1.05, bottom=0.02, wspace=0.1)
    output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(output, dpi=110)
    plt.close(fig)
    return output


if __name__ == "__main__":
    print(plot(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_OUTPUT))
