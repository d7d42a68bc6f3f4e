"""``toftwin calibrate brdf DATA.csv --model ... --out FILE.yaml``."""

from __future__ import annotations

import json

import numpy as np
import yaml
from typer.testing import CliRunner

from service.cli import app
from sim_core.materials import make_material
from tests.calibration.brdf.synthetic import measure

runner = CliRunner()


def _write_csv(path, table, wavelength_nm=None):
    rows = ["incidence_zenith_deg,reflection_zenith_deg,azimuth_difference_deg,brdf_per_sr"
            + (",wavelength_nm" if wavelength_nm else "")]
    for a, b, c, y in zip(table.incidence_zenith_deg, table.reflection_zenith_deg,
                          table.azimuth_difference_deg, table.brdf_per_sr, strict=True):
        rows.append(f"{a},{b},{c},{float(y)!r}" + (f",{wavelength_nm}" if wavelength_nm else ""))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def test_fits_and_writes_the_material_file(tmp_path):
    syn = measure(make_material("lambertian", albedo=0.25), 4, noise=0.03)
    data = tmp_path / "data.csv"
    _write_csv(data, syn.table, wavelength_nm=850)
    out = tmp_path / "fit.yaml"
    res = runner.invoke(app, ["calibrate", "brdf", str(data), "--model", "lambertian",
                              "--wavelength-nm", "850", "--seed", "4", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "albedo" in res.stdout and "e_fit" in res.stdout
    assert f"outliers flagged: {int(syn.outlier.sum())} of 200" in res.stdout
    written = yaml.safe_load(out.read_text(encoding="utf-8"))
    assert written["kind"] == "lambertian"
    assert abs(written["params"]["albedo"] - 0.25) < 0.01 * 0.25
    assert written["fit"]["wavelength_nm"] == 850.0
    assert np.array_equal([s["outlier"] for s in written["fit"]["samples"]], syn.outlier)


def test_fix_pins_a_parameter(tmp_path):
    syn = measure("black-glossy-tile", 1, noise=0.03)
    data = tmp_path / "data.csv"
    _write_csv(data, syn.table)
    out = tmp_path / "fit.yaml"
    res = runner.invoke(app, ["calibrate", "brdf", str(data), "--model", "cook-torrance",
                              "--fix", "n2=1.46", "--fix", "kd=0.07", "--out", str(out)])
    assert res.exit_code == 0, res.output
    written = yaml.safe_load(out.read_text(encoding="utf-8"))
    assert written["params"]["n2"] == 1.46 and written["params"]["kd"] == 0.07
    assert written["fit"]["fixed"] == {"n2": 1.46, "kd": 0.07}
    assert "fixed" in res.stdout
    # issue 27: every parameter's verdict beside the material file, the held ones said
    verdicts = json.loads((tmp_path / "fit.verdicts.json").read_text(encoding="utf-8"))
    assert set(verdicts) == {"params.kd", "params.ks", "params.m", "params.n2"}
    for key in ("params.n2", "params.kd"):
        assert verdicts[key]["verdict"] == "not determined" and "--fix" in verdicts[key]["reason"]
    counts = {v: sum(1 for x in verdicts.values() if x["verdict"] == v)
              for v in ("determined", "not determined", "unexplained")}
    assert (f"4 keys: {counts['determined']} determined, 2 not determined, "
            f"{counts['unexplained']} unexplained") in res.stdout
    assert "params.n2: not determined: held at 1.46 (--fix), not fitted" in res.stdout


def test_bad_input_exits_2_with_the_field(tmp_path):
    data = tmp_path / "data.csv"
    data.write_text("incidence_zenith_deg,reflection_zenith_deg,brdf_per_sr\n30,30,0.5\n")
    out = tmp_path / "fit.yaml"
    res = runner.invoke(app, ["calibrate", "brdf", str(data), "--model", "lambertian",
                              "--out", str(out)])
    assert res.exit_code == 2
    assert "azimuth_difference_deg" in res.output and not out.exists()
    for args in (["--model", "phong"], ["--model", "lambertian", "--fix", "albedo"]):
        res = runner.invoke(app, ["calibrate", "brdf", str(data), *args, "--out", str(out)])
        assert res.exit_code == 2, res.output
    assert "--fix" in res.output
