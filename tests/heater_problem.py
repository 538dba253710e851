"""The example heater (``fmus/examples/heater``) with its ambient temperature measured: its
problem file's text, for the tests of measured disturbances (each varies it)."""

from __future__ import annotations

from typing import Any

from tests.toml_text import toml_text


def heater_doc() -> dict[str, Any]:
    """P [W] -> T [degC], Ts = 20 s, the ambient ``T_in`` [degC] measured: the FMU's tunable
    parameter ``T_amb``, changing by at most 0.5 degC per sample (a new document each call,
    for a test to edit)."""
    return {
        "problem": {"name": "heater", "Ts": 20.0},
        "inputs.P": {"unit": "W", "min": 0.0, "max": 2000.0, "hold": [3, 60]},
        "outputs.T": {"unit": "degC", "min": 15.0, "max": 80.0},
        "disturbances.T_in": {"unit": "degC", "min": 5.0, "max": 35.0, "variable": "T_amb",
                              "rate": 0.5, "hold": [5, 80]},
    }


#: :func:`heater_doc` as the problem file's text.
HEATER = toml_text(heater_doc())
