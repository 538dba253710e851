"""What a live run takes for a plausible measurement: the problem's ``valid``, ``rate`` and
``frozen`` keys (read, checked, travelling in the JSON form), the screen that applies them
sample by sample, and a ``--problem`` beside a model's own problem (its safe values and
checks used, what the model was trained on compared)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from controllers.errors import ProblemFileError
from controllers.problem_file import load, problem_from_dict
from cosim.core.errors import CosimError
from cosim.core.pacing import Reading
from cosim.live.screen import Screen, reason_key
from tests.cosim.live.conftest import ROOT, problem_with

KEYS = {"h1": "valid = [-0.1, 2.5]\nrate = 0.2\nfrozen = 3", "h2": "frozen = 4",
        "qa": "safe = 0.0"}


@pytest.fixture
def plausible(tmp_path: Path) -> Path:
    return problem_with(tmp_path / "plausible.toml", KEYS)


def test_keys_are_read_and_travel(plausible: Path) -> None:
    p = load(plausible)
    h1, h2 = p.channel("h1"), p.channel("h2")
    assert (h1.valid, h1.rate, h1.frozen, h2.frozen, h2.valid) == ((-0.1, 2.5), 0.2, 3, 4, None)
    assert p.channel("qa").safe == 0.0
    back = problem_from_dict(p.to_dict())
    assert back == p and not p.differences(back)


@pytest.mark.parametrize(("signal", "line", "words"), [
    ("h1", "valid = [2.0, 1.0]", "'valid' (the range a measurement can have) must be [low, "
                                 "high] with low < high"),
    ("h1", "valid = 3", "'valid' must be a list of two numbers"),
    ("h1", "frozen = 1", "'frozen' must be 0 (off) or a whole number of samples from 2"),
    ("h1", "rate = 0", "'rate' (the largest change per sample) must be in (0, max - min"),
    ("qa", "frozen = 3", "unknown key 'frozen' in [inputs.qa] (valid, frozen and rate are for "
                         "outputs and disturbances)"),
    ("h2", "safe = 0.5", "unknown key 'safe' in [outputs.h2] (safe is for inputs)"),
])
def test_bad_keys_name_file_and_line(tmp_path: Path, signal: str, line: str,
                                     words: str) -> None:
    path = problem_with(tmp_path / "bad.toml", {signal: line})
    with pytest.raises(ProblemFileError) as err:
        load(path)
    header = next(i for i, ln in enumerate(path.read_text().splitlines(), start=1)
                  if ln.endswith(f".{signal}]"))
    assert str(err.value).startswith(f"{path}:{header + 1}:"), str(err.value)
    assert words in str(err.value)


def test_screen_refuses_what_the_problem_says_no_level_can_do(plausible: Path) -> None:
    """valid, rate (times the samples since the last value used) and frozen, each a reason of
    its own; a signal already stale keeps its reason; values of a fresh sample pass."""
    p = load(plausible)
    screen = Screen((*p.outputs, *p.disturbances), p.Ts, p.output_names)

    def sample(t: float, h1: float, h2: float, stale: dict | None = None) -> dict:
        return screen(Reading({"h1": h1, "h2": h2}, dict(stale or {})), t).stale

    assert sample(0, 0.60, 0.50) == {}
    assert reason_key(sample(25, 2.60, 0.51)["h1"]) == "outside its valid range"
    assert reason_key(sample(50, 1.10, 0.52)["h1"]) == "faster than its rate"  # 0.5 > 0.4
    assert sample(75, 0.75, 0.53) == {}          # 0.15 in 3 samples since 0.60: plausible
    assert sample(100, 0.75, 0.53, {"h2": "status Bad"}) == {"h2": "status Bad"}
    why = sample(125, 0.75, 0.54)
    assert list(why) == ["h1"] and why["h1"].startswith("frozen (0.75 m for 3 samples")
    assert sample(150, 0.76, 0.54) == {}          # moved again: fresh; h2 at 2 of its 4
    assert math.isclose(screen.last["h1"][0], 0.76)


def test_problem_beside_the_models_own_is_honoured(tmp_path: Path, plausible: Path) -> None:
    """The shipped model's embedded problem declares no safe value: a --problem that agrees
    on what the model was trained on brings its safe values and checks; one that changes a
    unit or a box is refused, naming the difference."""
    from controllers.model import GRUModel
    from cosim.adapters.problems import problem_for

    model = GRUModel.load(ROOT / "controllers" / "models" / "fourtank_gru.json")
    assert model.problem.channel("qa").safe is None
    used = problem_for(model, plausible)
    assert used.channel("qa").safe == 0.0 and used.channel("h1").frozen == 3
    assert used.source == str(plausible) and used.mpc == model.problem.mpc
    for old, new, words in (('unit = "m"', 'unit = "cm"', "h2.unit 'm' vs 'cm'"),
                            ("max = 2.0", "max = 3.0", "h2.max 2.0 vs 3.0")):
        head, _, tail = plausible.read_text().partition("[outputs.h2]")
        other = tmp_path / "other.toml"
        other.write_text(head + "[outputs.h2]" + tail.replace(old, new, 1))
        with pytest.raises(CosimError, match="contradicts the problem of") as err:
            problem_for(model, other)
        assert words in str(err.value), str(err.value)
