"""The robust MPC's design described once (cosim_adapters.mpc_options.MPCOptions)."""

from __future__ import annotations

import json

import pytest

from cosim.core.errors import CosimError
from cosim_adapters.mpc_options import LAW_DEFAULTS, MPCOptions
from cosim_adapters.robust_mpc import RobustMPCController


@pytest.mark.parametrize("law", ["tracking", "paper"])
def test_the_law_fills_its_defaults(law: str) -> None:
    o = MPCOptions.from_mapping({"law": law})
    assert {k: getattr(o, k) for k in LAW_DEFAULTS[law]} == LAW_DEFAULTS[law]
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
    with pytest.raises(CosimError, match=message) as err:
        MPCOptions.from_mapping(options)
    assert "\n" not in str(err.value)


def test_the_controller_takes_the_description_or_its_keys() -> None:
    by_keys = RobustMPCController(law="paper", N=10)
    by_object = RobustMPCController(options=MPCOptions.from_mapping({"law": "paper", "N": 10}))
    assert by_keys.options == by_object.options and by_keys.fhocp.N == 10
    summary = by_keys.summary()
    assert summary["options"]["N"] == 10 and summary["options"]["law"] == "paper"
    json.dumps(summary["options"])
    over = RobustMPCController(options=by_keys.options, N=12)   # a key over the object
    assert over.options.N == 12 and over.options.law == "paper"
