"""A third law is one folder (issue 59): the toy ``steady`` law of ``tests/controllers/laws/
steady`` (its spec, its step, its hypotheses, its C file) runs through ``cosim run``,
``cosim certify``, ``cosim tune`` and ``cosim export-fmu`` without a line outside its folder,
and its controller FMU gives the Python law's inputs to the bit."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import cosim
from controllers.model import DEFAULT_MODEL
from cosim.cli import main

LAW = "tests.controllers.laws.steady"


@pytest.fixture(scope="module", autouse=True)
def _registry() -> Iterator[None]:
    """The laws registered before this module, again after it: the toy law, registered when
    its module is named, would otherwise be listed by every later test of the worker (the
    unknown-law message names the known laws)."""
    from controllers import laws

    before = dict(laws._REGISTERED)
    yield
    laws._REGISTERED.clear()
    laws._REGISTERED.update(before)


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("steady") / "steps.csv"
    path.write_text("time,ref.h1,ref.h2\n0,0.7,0.7\n500,0.9,0.8\n1000,,\n")
    return path


def test_it_runs_and_its_fmu_gives_its_inputs(scenario: Path, tmp_path: Path) -> None:
    python = cosim.run(scenario, options={"law": LAW}, figure=False)
    assert python.status == "ok", python.reason
    info = python.summary["controller_summary"]
    assert info["law"] == "steady" and info["steady_steps"] == 41
    fmu = cosim.export_fmu(out=tmp_path / "Steady.fmu", options={"law": LAW})
    exported = cosim.run(scenario, controller=str(fmu), figure=False)
    assert exported.status == "ok", exported.reason
    a, b = python.to_pandas(), exported.to_pandas()
    for name in ("ctrl.qa", "ctrl.qb", "plant.h1", "plant.h2"):
        np.testing.assert_array_equal(a[name].to_numpy(), b[name].to_numpy())
    # the static inverse holds each set-point's equilibrium input: the levels settle there
    assert abs(a["plant.h1"].iloc[-1] - 0.9) < 0.1


def test_certify_and_tune_take_it(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    code = main(["certify", "--law", LAW, "--setpoint", "0.8,0.8"])
    out = capsys.readouterr().out
    assert code in (0, 1) and "steady-state law: the design's certificate" in out, out
    model = tmp_path / "model.json"
    shutil.copy(DEFAULT_MODEL, model)
    result = cosim.tune(model, law=LAW, workers=1)
    assert result.options["law"] == LAW and result.chosen in result.rows
