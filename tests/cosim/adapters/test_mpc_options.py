"""The robust MPC's design described once (controllers.mpc_options.MPCOptions)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from controllers import laws
from controllers.errors import OptionError, ProblemFileError
from controllers.mpc_options import MPCOptions
from controllers.problem_file import load, problem_from_dict
from cosim.adapters.robust_mpc import RobustMPCController
from cosim.core.errors import CosimError
from tests.fourtank_problem import with_table


@pytest.mark.parametrize("law", ["tracking", "paper"])
def test_the_law_fills_its_defaults(law: str) -> None:
    o = MPCOptions.from_mapping({"law": law})
    defaults = laws.spec(law).defaults
    assert {k: getattr(o, k) for k in defaults} == defaults
    assert MPCOptions.from_mapping({"law": law, "N": 7}).N == 7


def test_round_trip_through_plain_data() -> None:
    o = MPCOptions.from_mapping({"law": "tracking", "du_weight": {"qa": 2.0},
                                 "R": 0.02, "certificate": "require"})
    assert MPCOptions.from_mapping(json.loads(json.dumps(o.to_dict()))) == o
    with pytest.raises(AttributeError):
        o.N = 3   # frozen: one design, not a bag of mutable settings


@pytest.mark.parametrize(("options", "message"), [
    ({"horizon": 5}, "has no option 'horizon'"),
    ({"law": "offset-free"}, "option law='offset-free': expected one of"),
    ({"governor": True}, 'option governor=True belongs to law="paper"'),
    ({"law": "paper", "alpha_c": 0.1}, 'option alpha_c=0.1 belongs to law="tracking"'),
    ({"certificate": "maybe"}, "option certificate='maybe'"),
    ({"max_iter": 0}, "option max_iter=0: expected an integer"),
    ({"du_weight": -1}, "option du_weight=-1"),
    ({"offset_weight": {"h1": 0}}, "option offset_weight="),
    ({"law": "paper", "offset_filter": 2}, "option offset_filter=2"),
])
def test_bad_options_are_one_line_errors(options: dict, message: str) -> None:
    with pytest.raises(OptionError, match=message) as err:
        MPCOptions.from_mapping(options)
    assert "\n" not in str(err.value)


def test_the_controller_takes_the_description_or_its_keys() -> None:
    by_keys = RobustMPCController(law="paper", N=10)
    by_object = RobustMPCController(options=MPCOptions.from_mapping({"law": "paper", "N": 10}))
    assert by_keys.mpc.options == by_object.mpc.options and by_keys.mpc.fhocp.N == 10
    summary = by_keys.summary()
    assert summary["options"]["N"] == 10 and summary["options"]["law"] == "paper"
    json.dumps(summary["options"])
    over = RobustMPCController(options=by_keys.mpc.options, N=12)   # a key over the object
    assert over.mpc.options.N == 12 and over.mpc.options.law == "paper"


# -- the problem's [mpc] table: the tuning chosen for the plant ---------------------------------

def test_the_problems_mpc_table_tunes_the_controller_and_options_override_it(
        tmp_path: Path) -> None:
    path = with_table(tmp_path, "mpc", "N = 12\nR = 0.02\ncontrol_horizon = 5\n")
    problem = load(path)
    assert problem.mpc == {"N": 12, "R": 0.02, "control_horizon": 5}
    assert problem_from_dict(json.loads(json.dumps(problem.to_dict()))) == problem
    tuned = RobustMPCController(problem=path)        # the shipped model's problem, retuned
    o = tuned.mpc.options
    assert (o.N, o.R, o.option("control_horizon")) == (12, 0.02, 5)
    assert tuned.mpc.fhocp.N == 12
    over = RobustMPCController(problem=path, N=10)   # an option given wins
    assert (over.mpc.options.N, over.mpc.options.R) == (10, 0.02)
    paper = RobustMPCController(problem=path, law="paper")   # the other law's keys left out
    assert "control_horizon" not in paper.mpc.options.law_options
    assert paper.mpc.options.N == 12
    plain = RobustMPCController()                    # the model's own problem: no [mpc]
    assert laws.spec("tracking").defaults["N"] == plain.mpc.options.N


@pytest.mark.parametrize(("table", "anchor", "message"), [
    ("du_weight = -1\n", "du_weight = -1", "[mpc] option du_weight=-1: expected"),
    ("horizon = 3\n", "horizon = 3", "[mpc] controller 'robust-mpc' has no option 'horizon'"),
    ('law = "fast"\n', 'law = "fast"', "[mpc] option law='fast': expected one of"),
])
def test_a_bad_mpc_table_names_the_problem_file_and_line(tmp_path: Path, table: str,
                                                         anchor: str, message: str) -> None:
    path = with_table(tmp_path, "mpc", "N = 12\n" + table)
    text = path.read_text()
    line = text[:text.index(anchor)].count("\n") + 1
    with pytest.raises(CosimError) as err:
        RobustMPCController(problem=path)
    assert str(err.value).startswith(f"{path}:{line}: {message}"), err.value
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(("table", "message"), [
    ("N = 1979-05-27\n", "[mpc] 'N' must be a number, string, boolean, list or table"),
    ("Q = [1.0, nan]\n", "[mpc] 'Q' must be finite"),
])
def test_a_value_toml_has_but_json_lacks_is_refused_when_read(tmp_path: Path, table: str,
                                                              message: str) -> None:
    path = with_table(tmp_path, "mpc", table)
    line = path.read_text().count("\n")
    with pytest.raises(ProblemFileError, match=re.escape(f"{path}:{line}: {message}")):
        load(path)


def test_a_tuned_model_keeps_its_mpc_table_under_a_problem_file_without_one(
        tmp_path: Path) -> None:
    from controllers.model import DEFAULT_MODEL
    from tests.fourtank_problem import PATH

    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    doc["problem"]["mpc"] = {"N": 12}
    model = tmp_path / "tuned.json"
    model.write_text(json.dumps(doc))
    assert RobustMPCController(model=model).mpc.options.N == 12
    assert RobustMPCController(model=model, problem=PATH).mpc.options.N == 12
    retuned = with_table(tmp_path, "mpc", "N = 14\n")
    assert RobustMPCController(model=model, problem=retuned).mpc.options.N == 14
