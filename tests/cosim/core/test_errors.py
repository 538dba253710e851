"""The errors a worker process raises reach its parent whole: every error class of the library
with arguments of its own pickles back to an equal error (``cosim tune``'s closed loops and a
campaign's runs run in workers; a refusal there once surfaced as a pickling traceback)."""

from __future__ import annotations

import pickle

import pytest

from controllers.certification.grade import NotUsable
from cosim.core.errors import CosimError, FmuError, ParameterError


@pytest.mark.parametrize("error", [
    NotUsable("mpc", "stability index nu = 9.8 >= 1; fix: train it"),
    ParameterError("step_timeout", " must be positive"),
    FmuError("plant: fmi2DoStep failed", "fmi2DoStep", 3),
    CosimError("one line")])
def test_an_error_pickles_to_the_same_error(error: Exception) -> None:
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is type(error) and str(back) == str(error)
    assert vars(back) == vars(error)
    if isinstance(error, NotUsable):
        assert str(back).startswith("controller 'mpc': the model is not usable: ")
