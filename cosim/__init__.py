"""Co-simulation of plant FMUs with controllers: master, scenarios, results, campaigns, CLI.

The Python API (the twins of the ``cosim`` commands)::

    import cosim

    out = cosim.run("scenarios/paper_steps.csv")            # robust MPC on the four-tank FMU
    df = out.to_pandas()                                     # results.csv as a DataFrame
    out.summary["kpis"]["violations"], out.status

    campaign = cosim.run_campaign("scenarios/campaigns/theorem.toml", workers=2)
    campaign.table                                           # runs.parquet as a DataFrame

    cosim.export_fmu(out="Controller.fmu")                   # the robust MPC as an FMU
    cosim.tune("models/plant_gru.json", save=True)           # its weights, chosen on the model

Names are imported on first use, so that ``import cosim`` (and ``cosim --help``) stays fast.
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

__all__ = [
    "CampaignResult",
    "Component",
    "CosimError",
    "FmuComponent",
    "Master",
    "OutputError",
    "RunOutput",
    "RunResult",
    "Signal",
    "SimulationFailed",
    "__version__",
    "export_fmu",
    "load_scenario",
    "run",
    "run_campaign",
    "tune",
]

_EXPORTS = {
    "run": ("cosim.api", "run"),
    "export_fmu": ("cosim.api", "export_fmu"),
    "RunOutput": ("cosim.api", "RunOutput"),
    "run_campaign": ("cosim.campaign", "run_campaign"),
    "tune": ("cosim.tuning", "tune"),
    "CampaignResult": ("cosim.campaign", "CampaignResult"),
    "Master": ("cosim.core.master", "Master"),
    "RunResult": ("cosim.core.master", "RunResult"),
    "Component": ("cosim.core.component", "Component"),
    "Signal": ("cosim.core.component", "Signal"),
    "FmuComponent": ("cosim.core.fmu", "FmuComponent"),
    "load_scenario": ("cosim.core.scenario", "load"),
    "CosimError": ("cosim.core.errors", "CosimError"),
    "SimulationFailed": ("cosim.core.errors", "SimulationFailed"),
    "OutputError": ("cosim.core.errors", "OutputError"),
}


def __getattr__(name: str) -> Any:
    """Import an exported name on first use (PEP 562)."""
    try:
        module, attr = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'cosim' has no attribute {name!r}") from None
    import importlib

    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
