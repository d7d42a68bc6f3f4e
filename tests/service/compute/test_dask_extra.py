"""Dask's ``distributed`` is the ``dask`` extra, not a dependency: without it a ``dask://``
executor is refused at start naming the extra, before anything is written.

The shared venv has the extra installed, so its absence is made here: ``sys.modules['distributed']
= None`` makes every ``import distributed`` fail as it does where the package is missing (in
this process through ``monkeypatch``, in a subprocess through ``python -c``).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from pydantic import ValidationError

from service.compute.executors import DaskExecutor
from service.settings import Settings

TOKEN = "test-token-0123456789"
ADDRESS = "dask://127.0.0.1:8786"
ROOT = Path(__file__).resolve().parents[3]
#: run the CLI with Dask's distributed unimportable
NO_DASK = ("import sys; sys.modules['distributed'] = None; sys.argv = ['toftwin'] + sys.argv[1:]; "
           "from toftwin_cli import main; main()")


@pytest.fixture
def no_distributed(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)


@pytest.mark.parametrize("source", ["argument", "environment"])
def test_settings_refuse_a_dask_executor_without_distributed_naming_the_extra(
        no_distributed, monkeypatch, source):
    monkeypatch.setenv("TOFTWIN_EXECUTOR", ADDRESS if source == "environment" else "local")
    with pytest.raises(ValidationError) as exc:
        Settings(token=TOKEN, **({"executor": ADDRESS} if source == "argument" else {}))
    (error,) = exc.value.errors()
    assert error["loc"] == ("executor",)
    assert "distributed" in error["msg"] and "pip install -e '.[dask]'" in error["msg"]
    # the other executors need nothing more
    assert Settings(token=TOKEN, executor="thread").executor == "thread"


def test_the_dask_executor_itself_names_the_extra(no_distributed):
    with pytest.raises(ImportError, match=r"pip install -e '\.\[dask\]'"):
        DaskExecutor("tcp://127.0.0.1:8786")


def _toftwin(args: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    full = {**os.environ, "COLUMNS": "400", "TOFTWIN_TOKEN": TOKEN, **env}
    full["PYTHONPATH"] = os.pathsep.join([str(ROOT), full.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-c", NO_DASK, *args], cwd=cwd, env=full,
                          capture_output=True, text=True, timeout=60)


def test_serve_with_a_dask_executor_and_no_distributed_exits_2_writing_nothing(tmp_path):
    """(``TOFTWIN_EXECUTOR`` reaches the same check: the settings test above.)"""
    data = tmp_path / "data"
    res = _toftwin(["serve", "--data-dir", str(data), "--executor", ADDRESS], {}, tmp_path)
    text = " ".join(res.stderr.split())
    assert res.returncode == 2, res.stderr
    assert "TOFTWIN_EXECUTOR" in text and "distributed" in text and "dask extra" in text, text
    assert not data.exists()
    assert list(tmp_path.iterdir()) == []


def test_bench_campaign_dask_without_distributed_exits_2_before_any_run(tmp_path):
    res = _toftwin(["bench", "campaign", "--dask", "--poses", "1"], {}, tmp_path)
    text = " ".join(res.stderr.split())
    assert res.returncode == 2, res.stderr + res.stdout
    assert "--dask" in text and "distributed" in text and "dask extra" in text, text
    assert "local executor" not in res.stdout  # refused before the first configuration


@pytest.mark.dask
def test_with_distributed_installed_a_dask_executor_is_a_scheduler_address():
    """Where the extra is installed (the README's test venv) the same value is accepted."""
    s = Settings(token=TOKEN, executor="dask://10.0.0.5:8786")
    assert s.dask_address == "tcp://10.0.0.5:8786"
