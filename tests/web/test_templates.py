"""The templates the page and the report share, on data of known values."""

from __future__ import annotations

from service.export.report import explained_rows, unexplained_summary
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


def _unexplained(channel: str, shape: str, where: str, mean: float, share: float) -> dict:
    comp = {"shape": shape, "where": where, "share": share, "pixels": 900, "mean": mean,
            "rms": abs(mean), "noise_rms": 1.0}
    return {"channel": channel, "by": f"{channel} beyond", "where": {
        "unit": "mm" if channel == "depth" else "grey levels", "components": [comp]},
        "text": f"{channel} beyond: {shape} on {where}"}


def test_the_unexplained_residual_shows_per_pose_and_in_one_line_for_the_campaign():
    first = [_row(i, 0.004, 0.003, 0.001) for i in range(5)]
    for i, mean in enumerate((3.0, 3.4, 3.2, 2.0)):  # pose 4 within the ceiling
        first[i]["metrics"]["explained"]["unexplained"] = [
            _unexplained("depth", "offset", "the compared objects", mean, 0.9)]
    first[3]["metrics"]["explained"]["unexplained"] = [
        _unexplained("depth", "edges", "silhouette edges", 1.0, 0.7),
        _unexplained("grey", "dark", "dark pixels next to bright ones", 9.0, 0.6)]
    summary = unexplained_summary(first)
    assert summary == ("unexplained residual on 4 of 5 poses: depth on 4 (a common offset of "
                       "+3.2 mm over the compared objects (median) on 3); grey on 1 (excess on "
                       "dark pixels next to bright ones on 1)")
    rows, medians = explained_rows(first)
    html = environment().get_template("_explained_fragment.html").render(
        rows=rows, medians=medians, fit_verdicts={}, summary=summary)
    assert summary in html
    cells = [c.split("</td>")[0] for c in html.split("<td")[1:]]
    pose3 = html.split("<tr>")[5]  # header, then poses 0.. 3
    assert "depth beyond: edges on silhouette edges<br>grey beyond: dark on dark" in pose3
    assert 'class="unexplained">-' in html.split("<tr>")[6]  # pose 4: nothing unexplained
    assert len(cells) > 10


def test_a_campaign_within_the_ceiling_says_so():
    first = [_row(i, 0.004, 0.001, 0.001) for i in range(3)]
    for r in first:
        r["metrics"]["explained"].update(fitted={"depth_rmse_m": 0.001}, unexplained=[])
    assert unexplained_summary(first) == (
        "no unexplained residual: all 3 poses within the noise ceiling")
    assert unexplained_summary([]) is None


def test_the_views_the_object_fit_left_out_are_listed_with_why():
    dropped = [{"turntable_angle_deg": -27.0, "reason": "163 usable pixels < 300 <i>"},
               {"turntable_angle_deg": 0.5, "reason": "reduced chi-square 7.26"}]
    html = environment().get_template("_explained_fragment.html").render(
        rows=[], medians=None, fit_verdicts={}, dropped_views=dropped)
    items = [li.split("</li>")[0] for li in html.split("<li>")[1:]]
    assert items == ["-27 deg: 163 usable pixels &lt; 300 &lt;i&gt;",
                     "0.5 deg: reduced chi-square 7.26"]
    # none left out: nothing said
    html = environment().get_template("_explained_fragment.html").render(
        rows=[], medians=None, fit_verdicts={}, dropped_views=[])
    assert "left out" not in html
