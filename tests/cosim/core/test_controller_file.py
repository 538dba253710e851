"""A controller described in one file (cosim.core.controller_file): written by every run,
read back by --controller FILE.json, in cosim run and in a campaign."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.core import controller_file, registry
from cosim.core.errors import CosimError

ROOT = Path(__file__).resolve().parents[3]
MODEL = ROOT / "controllers" / "models" / "fourtank_gru.json"
SHORT = "time,ref.h1,ref.h2\n0,0.65,0.65\n60,0.7,\n150,,\n"


def run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str]:
    code = main(["run", *argv, "--quiet"])
    return code, capsys.readouterr().err


@pytest.fixture
def model(tmp_path: Path) -> Path:
    """A private copy of the shipped model (a test changes it)."""
    return Path(shutil.copy(MODEL, tmp_path / "gru.json"))


def test_a_run_recorded_runs_again_the_same(tmp_path: Path, fmu2_path: Path, model: Path,
                                            capsys: pytest.CaptureFixture) -> None:
    """The robust MPC with non-default options: its controller.json (the options given, the
    model fingerprinted) runs the same closed loop to the bit, from another folder; an
    --option given with the file overrides its value."""
    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    first = tmp_path / "first"
    code, err = run(capsys, str(scenario), "--plant", str(fmu2_path), "--model", str(model),
                    "--option", "N=30", "--option", "du_weight=0.2", "--out", str(first))
    assert code == 0, err
    doc = json.loads((first / "controller.json").read_text())
    assert doc["format"] == controller_file.FORMAT and doc["controller"] == "robust-mpc"
    assert doc["options"]["N"] == 30 and doc["options"]["model"] == str(model.resolve())
    assert len(doc["files"]["model"]["sha256"]) == 64
    assert json.loads((first / "summary.json").read_text())["controller_file"] == \
        "controller.json"
    moved = Path(shutil.copy(first / "controller.json", tmp_path / "elsewhere.json"))
    code, err = run(capsys, str(scenario), "--plant", str(fmu2_path), "--controller",
                    str(moved), "--out", str(tmp_path / "again"))
    assert code == 0, err
    assert (tmp_path / "again" / "results.csv").read_bytes() == \
        (first / "results.csv").read_bytes()
    name, options = registry.expand(str(moved), {"N": 20})
    assert name == "robust-mpc" and options["N"] == 20 and options["du_weight"] == 0.2


def test_a_changed_model_is_refused_in_one_line(tmp_path: Path, fmu2_path: Path, model: Path,
                                                capsys: pytest.CaptureFixture) -> None:
    desc = controller_file.write(tmp_path / "ctrl.json",
                                 controller_file.describe("robust-mpc", {"model": str(model)}))
    model.write_text(model.read_text().replace('"Ts"', ' "Ts"', 1))   # retrained, say
    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    code, err = run(capsys, str(scenario), "--plant", str(fmu2_path), "--controller",
                    str(desc), "--out", str(tmp_path / "out"))
    assert code == 2 and err.count("\n") == 1
    assert f"{desc}: option 'model': {model.resolve()} changed since" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text, message", [
    ("[1, 2]", "a controller file is a JSON object"),
    ('{"format": "other"}', "key 'format': expected 'gru-mpc-controller/1'"),
    ('{"format": "gru-mpc-controller/1", "controller": "pi", "extra": 1}',
     "unknown key 'extra'"),
    ('{"format": "gru-mpc-controller/1", "controller": "x.json"}', "key 'controller'"),
    ('{"format": "gru-mpc-controller/1", "controller": "pi", "options": {"model": "m.json"},'
     ' "files": {"model": {"sha256": "00"}}}', "option 'model':"),
    ('{"format": "gru-mpc-controller/1",\n "controller": }', ":2:16: not JSON"),
])
def test_bad_controller_files_are_one_line_errors(tmp_path: Path, text: str,
                                                  message: str) -> None:
    path = tmp_path / "c.json"
    path.write_text(text)
    with pytest.raises(CosimError) as info:
        registry.create(str(path))
    assert str(info.value).startswith(str(path)) and message in str(info.value)
    assert "\n" not in str(info.value)


def test_python_objects_are_not_described(tmp_path: Path) -> None:
    """An option that is a Python object (the API) cannot be written: describe refuses it,
    and a run then writes no controller.json (summary: controller_file null)."""
    with pytest.raises(CosimError, match="option 'problem': object cannot be written"):
        controller_file.describe("pi", {"problem": object()})


def test_a_campaign_variant_takes_a_controller_file(tmp_path: Path) -> None:
    """Found beside the spec, checked when the spec is read."""
    from cosim.campaign import spec

    controller_file.write(tmp_path / "pi.json",
                          controller_file.describe("pi", {"pairing": "diagonal"}))
    (tmp_path / "s.csv").write_text(SHORT)
    text = ('[campaign]\nruns = 1\nscenario = "s.csv"\n\n[[variant]]\nname = "a"\n'
            'controller = "pi.json"\n')
    (tmp_path / "c.toml").write_text(text)
    loaded = spec.load(tmp_path / "c.toml")
    assert loaded.variants[0].controller == str(tmp_path / "pi.json")
    (tmp_path / "c.toml").write_text(text.replace("pi.json", "missing.json"))
    with pytest.raises(CosimError, match=re.escape("c.toml:7: controller = 'missing.json': ")):
        spec.load(tmp_path / "c.toml")


def test_a_campaign_runs_a_recorded_controller_as_cosim_run_does(
        tmp_path: Path, fmu2_path: Path, model: Path, capsys: pytest.CaptureFixture) -> None:
    """The engine expands the file when it plans (its model packed with the campaign, so a
    worker elsewhere needs none of this machine's files): the variant's run is the recorded
    run, to the bit."""
    from cosim.campaign import engine, store
    from cosim.campaign.spec import load
    from cosim.campaign.task import run_task

    (tmp_path / "s.csv").write_text(SHORT)
    code, err = run(capsys, str(tmp_path / "s.csv"), "--plant", str(fmu2_path), "--model",
                    str(model), "--option", "N=30", "--out", str(tmp_path / "one"))
    assert code == 0, err
    (tmp_path / "c.toml").write_text(
        f'[campaign]\nruns = 1\nscenario = "s.csv"\nplant = "{fmu2_path}"\n\n'
        '[[variant]]\nname = "recorded"\ncontroller = "one/controller.json"\n')
    plan = engine.prepare(load(tmp_path / "c.toml"))
    (task,) = plan.tasks
    assert task["controller"] == "robust-mpc" and task["options"]["N"] == 30
    assert task["options"]["model"] == "model_0.json" and "model_0.json" in plan.assets.files
    out = tmp_path / "out"
    for t in store.open_folder(plan, out, resume=False, force=False):
        store.write_run(out, plan.spec, t, run_task(t, plan.assets), None)
    (folder,) = (out / "runs").iterdir()
    assert (folder / "results.csv").read_bytes() == (tmp_path / "one" / "results.csv").read_bytes()
