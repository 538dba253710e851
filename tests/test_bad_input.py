"""Bad input at scale (hypothesis): the readers of scenarios, control problems, logs, model
files and variable maps, ``cosim run`` itself, and the controller FMU's inputs and
parameters, fed with generated damage to valid files and values.

Every case is success, or the user's error: a :class:`~cosim.core.errors.CosimError` or a
bad-input error of the numerical core (a ``ValueError`` subclass of
:class:`~controllers.errors.ControllersError`), one line, never another exception (which the
command line would show as a traceback) and never a hang (each example has a deadline);
``cosim run`` exits 0, or 2 with one line and the previous run's files untouched (1 only for
a run that started and failed, with its partial results). The controller FMU takes any
value: a refused set changes nothing, and its inputs to apply stay finite inside their box.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from controllers.errors import ControllersError  # noqa: E402
from cosim.core import scenario, varmap  # noqa: E402
from cosim.core.errors import CosimError, SimulationFailed  # noqa: E402
from cosim.core.logdata import read_log  # noqa: E402
from tests.cosim.pyfmu_models import MAP  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: Each example's time limit: a reader that takes longer is as good as hung.
DEADLINE_MS = 5000
#: Pieces the damage is made of: separators, quotes, control characters, numbers a parser
#: chokes on, names the files use.
PIECES = [*",\n\r\t\"'=[]{}.#-+eE0123456789 :", "nan", "inf", "-inf", "1e400", "1e-400",
          "-0", "0x1p3", "\x00", "\x1b[31m", "\u202e", "\u2028", "é", "😀", "\ufeff", "time",
          "ref.h1", "plant.qa", "sensor.h1.noise", "[inputs.qa]", "[outputs.h1]", "unit",
          "min", "max", "Ts", "true", "null", '"', "\\"]

SETTINGS = settings(max_examples=60, deadline=DEADLINE_MS, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


@st.composite
def damaged(draw: st.DrawFn, text: str) -> str:
    """``text`` with one to four edits: a piece inserted, a span deleted or replaced."""
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(text)))
        kind = draw(st.sampled_from(("insert", "delete", "replace")))
        piece = "".join(draw(st.lists(st.sampled_from(PIECES), min_size=1, max_size=4)))
        if kind == "insert":
            text = text[:i] + piece + text[i:]
        else:
            j = min(len(text), i + draw(st.integers(1, 12)))
            text = text[:i] + (piece if kind == "replace" else "") + text[j:]
    return text


#: What a number in a file may become.
ODD_NUMBERS = ["nan", "inf", "-inf", "1e300", "-1e300", "0", "-0", "1e-300", "-1", "", "1e15",
               "2147483648", "0.0.1", "1,5"]
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


@st.composite
def odd_numbers(draw: st.DrawFn, text: str) -> str:
    """``text`` with one to three of its numbers replaced by odd ones (:data:`ODD_NUMBERS`):
    the file stays well formed, its values do not."""
    spans = [m.span() for m in NUMBER.finditer(text)]
    chosen = sorted(set(draw(st.lists(st.integers(0, len(spans) - 1), min_size=1,
                                      max_size=3))), reverse=True)
    for k in chosen:
        i, j = spans[k]
        text = text[:i] + draw(st.sampled_from(ODD_NUMBERS)) + text[j:]
    return text


def bad(text: str) -> st.SearchStrategy[str]:
    """Damage to ``text``: its syntax (:func:`damaged`) or its values (:func:`odd_numbers`)."""
    return st.one_of(damaged(text), odd_numbers(text))


def _bad_input(call: Callable[[], Any]) -> None:
    """``call()`` succeeds, or raises the user's error in one line."""
    try:
        call()
    except CosimError as exc:
        assert not isinstance(exc, SimulationFailed), exc
        message = str(exc)
    except ControllersError as exc:
        assert isinstance(exc, ValueError), f"{type(exc).__name__}: {exc}"
        message = str(exc)
    else:
        return
    assert message and "\n" not in message and "\r" not in message, repr(message)


def _file(text: str, name: str) -> Path:
    folder = Path(tempfile.mkdtemp(prefix="cosim-bad-input-"))
    path = folder / name
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    return path


def _read(path: Path, read: Callable[[Path], Any]) -> None:
    try:
        _bad_input(lambda: read(path))
    finally:
        shutil.rmtree(path.parent, ignore_errors=True)


SCENARIO = (ROOT / "scenarios" / "leak_tank1.csv").read_text()
PROBLEM = (ROOT / "fmus" / "fourtank" / "problem.toml").read_text()
LOG = "time,qa,qb,h1,h2,split\n" + "".join(
    f"{25 * k},{4e-4 + 1e-5 * (k % 7)},{5e-4 - 1e-5 * (k % 5)},{0.6 + 0.01 * (k % 3)},"
    f"{0.7 - 0.01 * (k % 4)},{'train' if k < 30 else 'val' if k < 35 else 'test'}\n"
    for k in range(40))


#: The file readers fed with damage: a valid file's text, its name, the reader.
FILES = {
    "scenario": (SCENARIO, "sc.csv", scenario.load),
    "map": (MAP, "plant.map.toml", varmap.load),
    "log": (LOG, "log.csv", lambda path: read_log(path, ["qa", "qb"], ["h1", "h2"], Ts=25.0,
                                                  problem="fourtank")),
}


@pytest.mark.parametrize("kind", FILES)
@SETTINGS
@given(data=st.data())
def test_the_file_readers(kind: str, data: st.DataObject) -> None:
    text, name, read = FILES[kind]
    _read(_file(data.draw(bad(text)), name), read)


@SETTINGS
@given(bad(PROBLEM))
def test_the_problem_reader(text: str) -> None:
    from controllers import problem_file

    _bad_input(lambda: problem_file.loads(text, "problem.toml"))


MODEL = json.loads((ROOT / "controllers" / "models" / "fourtank_gru.json").read_text())
#: Values a model file's leaf may be replaced with.
ODD_VALUES = st.one_of(st.just(float("nan")), st.just(float("inf")), st.just(1e300),
                       st.just(-1e300), st.just(0.0), st.just(-1), st.just(""), st.just(None),
                       st.just([]), st.just({}), st.just("h1"), st.just(True),
                       st.lists(st.floats(allow_nan=True), max_size=3))


def _leaves(doc: Any, path: tuple = ()) -> list[tuple]:
    if isinstance(doc, dict):
        return [leaf for k, v in doc.items() for leaf in _leaves(v, (*path, k))] or [path]
    if isinstance(doc, list) and doc and not isinstance(doc[0], int | float):
        return [leaf for i, v in enumerate(doc) for leaf in _leaves(v, (*path, i))]
    return [path]


LEAVES = [leaf for leaf in _leaves(MODEL) if leaf]


@st.composite
def damaged_model(draw: st.DrawFn) -> str:
    """The shipped model with one to three values replaced (``nan`` written as JSON's
    ``NaN``), or a key dropped."""
    doc = json.loads(json.dumps(MODEL))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(LEAVES))
        parent = doc
        try:
            for key in path[:-1]:
                parent = parent[key]
            if draw(st.booleans()) or not isinstance(parent, dict):
                parent[path[-1]] = draw(ODD_VALUES)
            else:
                del parent[path[-1]]
        except (KeyError, IndexError, TypeError):
            continue
    return json.dumps(doc)


@settings(SETTINGS, max_examples=40)
@given(st.one_of(damaged_model(), damaged(json.dumps(MODEL)[:4000] + "]}")))
def test_the_model_reader(text: str) -> None:
    from controllers.model import GRUModel

    _read(_file(text, "model.json"), GRUModel.load)


@settings(SETTINGS, max_examples=25)
@given(text=bad("time,ref.h1,ref.h2\n0,0.6,0.6\n250,0.7,\n500,,\n"))
def test_cosim_run_refuses_a_damaged_scenario_and_keeps_the_previous_results(
        text: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The whole command: exit 0; or 2, one line, the previous run's files as they were;
    or 1 (a run that started and failed), one line, its partial results written."""
    from cosim.cli import main

    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    (out / "results.csv").write_text("the previous results\n")
    sc = _file(text, "sc.csv")
    try:
        code = main(["run", str(sc), "--controller", "pi", "--out", str(out), "--quiet",
                     "--no-figure"])
    finally:
        shutil.rmtree(sc.parent, ignore_errors=True)
    err = capsys.readouterr().err
    assert code in (0, 1, 2), err
    if code:
        assert err.count("\n") == 1 and "Traceback" not in err, err
    if code == 2:
        assert (out / "results.csv").read_text() == "the previous results\n"
    else:
        assert (out / "summary.json").is_file()


# -- the controller FMU's inputs and parameters ------------------------------------------------
ANY_FLOAT = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                      st.sampled_from([0.0, -0.0, 1e-320, 1e300, -1e300, 0.65, 2.0, 5.0]))


@pytest.fixture(scope="module")
def controller(controller_fmus: dict[int, Path]) -> Any:
    """The exported controller FMU (FMI 3), extracted once; instantiated per example."""
    from fmpy import extract

    folder = extract(str(controller_fmus[3]))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@settings(SETTINGS, max_examples=80)
@given(params=st.dictionaries(st.sampled_from(["offset_filter", "R.qa", "R.qb", "du_weight.qa",
                                               "offset_weight.h1"]), ANY_FLOAT, max_size=3),
       inputs=st.lists(st.tuples(ANY_FLOAT, ANY_FLOAT, ANY_FLOAT, ANY_FLOAT), min_size=1,
                       max_size=4))
def test_the_controller_fmu_takes_any_value(controller: str, params: dict,
                                            inputs: list) -> None:
    """Any parameters (set together: all or nothing, a refusal changes none of them) and
    any measurements and set-points, finite or not: every step's inputs to apply are finite
    and inside their box."""
    import fmpy
    from fmpy.fmi3 import FMU3Slave

    md = fmpy.read_model_description(controller)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    box = {v.name: (float(v.min), float(v.max)) for v in md.modelVariables
           if v.name in ("qa", "qb")}
    fmu = FMU3Slave(guid=md.instantiationToken, unzipDirectory=controller,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="mpc")
    fmu.instantiate()
    try:
        names = list(params)
        before = fmu.getFloat64([vr[n] for n in names])
        try:
            fmu.setFloat64([vr[n] for n in names], [params[n] for n in names])
        except Exception:
            assert fmu.getFloat64([vr[n] for n in names]) == before
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        for k, (h1, h2, r1, r2) in enumerate(inputs):
            fmu.setFloat64([vr["h1"], vr["h2"], vr["ref.h1"], vr["ref.h2"]], [h1, h2, r1, r2])
            fmu.doStep(currentCommunicationPoint=25.0 * k, communicationStepSize=25.0)
            for name, value in zip(("qa", "qb"), fmu.getFloat64([vr["qa"], vr["qb"]]),
                                   strict=True):
                low, high = box[name]
                assert math.isfinite(value) and low <= value <= high, (name, value)
        fmu.terminate()
    finally:
        fmu.freeInstance()
    assert np.isfinite(before).all()
