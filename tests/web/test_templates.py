"""The templates the page and the report share, on data of known values."""

from __future__ import annotations

from service.export.report import explained_rows
from service.web import environment


def _row(pose_index: int, nominal_m: float, fitted_m: float, ceiling_m: float) -> dict:
    twins = {"nominal": (nominal_m, 30.0), "fitted": (fitted_m, 38.0), "ceiling": (ceiling_m,
                                                                                   41.0)}
    explained = {t: {"depth_rmse_m": d, "grey_psnr_db": g} for t, (d, g) in twins.items()}
    explained["explained"] = {"depth": 0.75, "grey": 0.5}
    return {"pose_index": pose_index, "turntable_deg": 10.0 * pose_index,
            "metrics": {"explained": explained}}


def test_the_explained_difference_shows_each_twin_in_millimetres_and_decibels_with_the_medians():
    rows, medians = explained_rows([_row(0, 0.004, 0.002, 0.001), _row(1, 0.006, 0.003, 0.001)])
    html = environment().get_template("_explained_fragment.html").render(
        rows=rows, medians=medians, fit_verdicts={})
    cells = [c.split("</td>")[0] for c in html.split("<td>")[1:]]
    # pose 0: nominal, fitted, ceiling depth RMSE [mm], then grey PSNR [dB], then explained
    assert cells[:10] == ["0", "0", "4.00", "2.00", "1.00", "30.00", "38.00", "41.00", "75 %",
                          "50 %"]
    median = html.split('class="median"')[1]
    assert "5.00" in median and "2.50" in median  # medians of 4 and 6 mm, of 2 and 3 mm


def test_a_campaign_without_the_object_fit_explains_nothing():
    rows, _ = explained_rows([])
    html = environment().get_template("_explained_fragment.html").render(rows=rows, medians=None,
                                                                       fit_verdicts={})
    assert "<table" not in html


def test_the_object_fit_s_verdicts_show_each_key_its_error_and_why():
    verdicts = {
        "mount.pose_offset.position_m": {"verdict": "determined",
                                         "std": [0.0002, 0.00015, 0.0004], "reason": None},
        "objects.body.reflectance_scale": {"verdict": "unexplained", "std": 0.02,
                                           "reason": "views +90 deg (chi-square 31.2) <b>"},
        "objects.pedestal.reflectance_scale": {"verdict": "not determined", "std": None,
                                               "reason": "too little signal"},
    }
    html = environment().get_template("_explained_fragment.html").render(
        rows=[], medians=None, fit_verdicts=verdicts)
    rows = html.split("<tr")[2:]
    assert len(rows) == 3
    assert 'class="determined"' in rows[0] and "0.0002, 0.00015, 0.0004" in rows[0]
    assert 'class="unexplained"' in rows[1] and "0.02" in rows[1]
    assert "chi-square 31.2) &lt;b&gt;" in rows[1]  # a reason is text, never markup
    assert 'class="not-determined"' in rows[2] and "<td class=\"num\">-</td>" in rows[2]
