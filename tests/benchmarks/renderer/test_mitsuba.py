"""The Mitsuba 3 comparison benchmark: a quick run where Mitsuba works, a clear error where not.

Mitsuba is an optional benchmark dependency (extra ``bench``); CI installs only ``.[dev]``, so
there the tests assert the RuntimeError that says how to install it. Nothing here is skipped.
"""

import importlib.util
import io
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from benchmarks.renderer import mitsuba as bm
from benchmarks.renderer import mitsuba_backend as backend

ROOT = Path(__file__).resolve().parents[3]


def _mitsuba_loads() -> tuple[bool, str]:
    """(True, "") if Mitsuba and its LLVM backend load; else (False, the RuntimeError text)."""
    try:
        backend.load_mitsuba()
    except RuntimeError as exc:
        return False, str(exc)
    return True, ""


def _assert_clear(msg: str) -> None:
    assert "pip install" in msg and "mitsuba" in msg.lower()
    assert "libllvm19" in msg and "DRJIT_LIBLLVM_PATH" in msg


@pytest.mark.slow
def test_quick_comparison_or_clear_error():
    console = Console(file=io.StringIO(), width=200)
    if importlib.util.find_spec("mitsuba") is None:
        with pytest.raises(RuntimeError) as err:
            bm.run_mitsuba_comparison(console, quick=True)
        _assert_clear(str(err.value))
        return
    ok, msg = _mitsuba_loads()
    if not ok:  # installed without a usable libLLVM: the same clear error
        with pytest.raises(RuntimeError) as err:
            bm.run_mitsuba_comparison(console, quick=True)
        _assert_clear(str(err.value))
        _assert_clear(msg)
        return

    res = bm.run_mitsuba_comparison(console, spps=(2,), bounces=(1, 2), quick=True)
    out = console.file.getvalue()
    assert "Speed and DC agreement" in out and "reference check" in out
    assert res["camera_mismatch_deg"] < 1e-3
    assert [(r["bounces"], r["spp"]) for r in res["rows"]] == [(1, 2), (2, 2)]
    for row in res["rows"]:
        for key in ("ours_s", "mitsuba_s", "ratio_ours_over_mitsuba", "scale", "rel_rmse",
                    "max_rel_err", "rel_rmse_blocks"):
            assert math.isfinite(row[key]) and row[key] >= 0.0, (key, row)
        assert 0.8 < row["scale"] < 1.25
        assert row["mitsuba_max_depth"] == row["bounces"] + 1
    # Direct light hardly has Monte Carlo noise: the two must agree closely already.
    direct = res["rows"][0]
    assert abs(direct["scale"] - 1.0) < 0.01 and direct["rel_rmse"] < 0.02
    ref = res["reference"]
    assert abs(ref["scale"] - 1.0) < 0.03
    assert ref["rel_rmse_over_noise"] < 1.5  # the difference is Monte Carlo noise
    tte = res["time_to_error"]
    for who in ("ours", "mitsuba"):
        assert math.isfinite(tte[who]["seconds_to_target"]) and tte[who]["seconds_to_target"] > 0
        assert all(e > 0 for e in tte[who]["rel_rmse_raw"])
    assert math.isfinite(tte["ratio_ours_over_mitsuba"])


def test_missing_mitsuba_raises_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # makes `import mitsuba` fail
    with pytest.raises(RuntimeError) as err:
        bm.run_mitsuba_comparison(Console(file=io.StringIO()), quick=True)
    _assert_clear(str(err.value))
    assert "not installed" in str(err.value)


def test_unloadable_libllvm_raises_clear_error(tmp_path):
    """A fresh process with a wrong DRJIT_LIBLLVM_PATH: Dr.Jit cannot start its LLVM backend."""
    code = (
        "from benchmarks.renderer.mitsuba_backend import load_mitsuba\n"
        "try:\n    load_mitsuba()\nexcept RuntimeError as e:\n    print('RTE:', e)\n"
        "else:\n    print('LOADED')\n"
    )
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": str(tmp_path / "libLLVM-nope.so")}
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "RTE:" in proc.stdout and "LOADED" not in proc.stdout, proc.stdout
    _assert_clear(proc.stdout)


def test_the_install_hint_names_the_bench_extra_from_the_clone(monkeypatch):
    from typer.testing import CliRunner

    from toftwin_cli import app

    assert 'pip install -c requirements/lock.txt -e ".[bench]"' in backend.INSTALL_HINT
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # makes `import mitsuba` fail
    res = CliRunner().invoke(app, ["bench", "mitsuba", "--spp", "1", "--bounces", "1",
                                   "--no-convergence"])
    assert res.exit_code == 1 and res.stdout == ""
    err = " ".join(res.stderr.split())
    assert 'pip install -c requirements/lock.txt -e ".[bench]"' in err, err
    assert "'toftwin'" not in err


def test_a_probe_that_aborts_is_reported_and_the_caller_goes_on():
    ok, detail = backend.probe_backend(backend.MITSUBA_VARIANT, None, timeout_s=60,
                                       code="import os, sys\nsys.stderr.write('LLVM ERROR: Cannot "
                                       "select: f32 = fminimum\\n  more\\n')\nos.abort()\n")
    assert not ok
    assert detail == "the probe was killed by SIGABRT: LLVM ERROR: Cannot select: f32 = fminimum"


def test_the_failure_message_names_the_library_its_version_and_what_to_install():
    detail = "the probe was killed by SIGABRT: LLVM ERROR: Cannot select: f32 = fminimum"
    for path, says in (("/usr/lib/x86_64-linux-gnu/libLLVM-15.so", "stop in LLVM 15's"),
                       ("/usr/lib/llvm-14/lib/libLLVM.so", "needs LLVM 15 or newer"),
                       ("/tmp/libfoo.so", "not a libLLVM Dr.Jit can load"),
                       (None, "no libLLVM shared library was found")):
        msg = backend.backend_failure_message(path, "found", detail)
        assert says in msg and detail in msg, msg
        assert path is None or path in msg
        _assert_clear(msg)


@pytest.mark.timeout(600)
def test_a_backend_that_cannot_run_is_an_error_naming_the_library_not_a_crash(tmp_path):
    """A fresh CLI process pointed at a library Dr.Jit cannot use: exit 1, the library, its
    version and what to install; no LLVM dump, no traceback."""
    fake = tmp_path / "libLLVM-15.so"
    fake.write_bytes(b"not a shared library")
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": str(fake)}
    proc = subprocess.run(
        [sys.executable, "-m", "toftwin_cli", "bench", "mitsuba", "--spp", "1", "--bounces", "1",
         "--no-convergence"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 1, proc.stderr
    assert proc.stdout == "" and "Traceback" not in proc.stderr
    err = " ".join(proc.stderr.split())
    _assert_clear(err)
    if importlib.util.find_spec("mitsuba") is None:
        assert "not installed" in err
    else:
        assert f"DRJIT_LIBLLVM_PATH names: {fake} (LLVM 15)" in err, err
        assert "the probe exited with code 1" in err


def test_scale_fit_and_errors():
    rng = np.random.default_rng(0)
    ours = rng.uniform(1.0, 2.0, (40, 48))
    agr = bm.agreement(ours, ours / 2.5)
    assert agr["scale"] == pytest.approx(2.5)
    assert agr["rel_rmse"] < 1e-12 and agr["max_rel_err"] < 1e-12
    assert agr["rel_rmse_blocks"] < 1e-12
    # noise in the second image does not bias the scale (it is fitted on block means)
    noisy = ours / 2.0 * (1.0 + 0.2 * rng.standard_normal(ours.shape))
    agr = bm.agreement(ours, noisy)
    assert agr["scale"] == pytest.approx(2.0, rel=0.01)
    assert 0.15 < agr["rel_rmse"] < 0.25
    assert agr["rel_rmse_blocks"] < 0.05
    assert bm.rel_rmse(ours * 1.1, ours) == pytest.approx(0.1)
    assert bm.block_means(np.arange(17 * 16.0).reshape(17, 16), 8).shape == (2, 2)


def test_loglog_crossing():
    t = np.array([1.0, 2.0, 4.0, 8.0])
    err = 0.2 / np.sqrt(t)
    x, extrapolated = bm.loglog_crossing(t, err, 0.1)
    assert x == pytest.approx(4.0) and not extrapolated
    x, extrapolated = bm.loglog_crossing(t, err, 0.05)  # beyond the sweep: fitted line
    assert x == pytest.approx(16.0) and extrapolated
    x, _ = bm.loglog_crossing(t, np.full(4, 0.1), 0.05)  # not decreasing
    assert math.isnan(x)


def test_find_libllvm_returns_the_newest_library_found_or_none():
    path = backend.find_libllvm()
    assert path is None or Path(path).is_file()
    found = backend.libllvm_candidates()
    assert (path is None) == (not found)
    versions = [backend.llvm_version(p) or 0 for p in found]
    assert versions == sorted(versions, reverse=True)


def test_cli_speed_table_as_json_or_clear_error(tmp_path):
    """``--spp``/``--bounces`` lists and ``--json``: rows of the speed table, or exit 1 and the
    install hint where Mitsuba does not load."""
    from typer.testing import CliRunner

    from toftwin_cli import app

    out = tmp_path / "mitsuba.json"
    res = CliRunner().invoke(app, ["bench", "mitsuba", "--spp", "1,2", "--bounces", "1",
                                   "--no-convergence", "--json", str(out)])
    ok, msg = _mitsuba_loads()
    if not ok:
        assert res.exit_code == 1 and not out.exists()
        _assert_clear(msg)
        return
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert [(r["spp"], r["bounces"]) for r in data["rows"]] == [(1, 1), (2, 1)]
    for row in data["rows"]:
        assert row["ours_s"] > 0 and row["mitsuba_s"] > 0
        assert row["ratio_ours_over_mitsuba"] == pytest.approx(row["ours_s"] / row["mitsuba_s"])
    assert data["reference"] is None and data["time_to_error"] is None
    assert data["tracer_backend"] in ("binding", "embreex")


@pytest.mark.parametrize("args", [["--spp", "16,x"], ["--spp", "0"], ["--bounces", "1,,2"]])
def test_cli_refuses_bad_lists_before_loading_anything(args):
    from typer.testing import CliRunner

    from toftwin_cli import app

    res = CliRunner().invoke(app, ["bench", "mitsuba", *args])
    assert res.exit_code == 2
    assert args[0] in res.output
