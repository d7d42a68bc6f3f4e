"""The templates the page and the report share, on data of known values."""

from __future__ import annotations

from service.export.report import verdict_rows
from service.web import environment


def _row(pose_index: int, nominal_m: float, fitted_m: float, ceiling_m: float) -> dict:
    twins = {"nominal": (nominal_m, 30.0), "fitted": (fitted_m, 38.0), "ceiling": (ceiling_m,
                                                                                   41.0)}
    explained = {t: {"depth_rmse_m": d, "grey_psnr_db": g} for t, (d, g) in twins.items()}
    explained["explained"] = {"depth": 0.75, "grey": 0.5}
    return {"pose_index": pose_index, "turntable_deg": 10.0 * pose_index,
            "metrics": {"explained": explained}}


def test_the_verdict_shows_each_twin_in_millimetres_and_decibels_with_the_medians():
    rows, medians = verdict_rows([_row(0, 0.004, 0.002, 0.001), _row(1, 0.006, 0.003, 0.001)])
    html = environment().get_template("_verdict_fragment.html").render(rows=rows,
                                                                       medians=medians)
    cells = [c.split("</td>")[0] for c in html.split("<td>")[1:]]
    # pose 0: nominal, fitted, ceiling depth RMSE [mm], then grey PSNR [dB], then explained
    assert cells[:10] == ["0", "0", "4.00", "2.00", "1.00", "30.00", "38.00", "41.00", "75 %",
                          "50 %"]
    median = html.split('class="median"')[1]
    assert "5.00" in median and "2.50" in median  # medians of 4 and 6 mm, of 2 and 3 mm


def test_a_campaign_without_the_object_fit_has_no_verdict():
    rows, _ = verdict_rows([])
    html = environment().get_template("_verdict_fragment.html").render(rows=rows, medians=None)
    assert "<table" not in html
