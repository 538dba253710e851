"""Campaigns: thousands of seeded closed-loop runs on Dask, with violation statistics.

``cosim campaign SPEC.toml`` and its Python twin :func:`run_campaign`. A campaign runs one
scenario many times with per-run draws (plant parameters, sensor perturbations, set-point
sequences, initial states) and once per controller variant, on a local Dask cluster or an
existing one, and reports a violation probability with a confidence bound, KPI
distributions and the failed runs grouped by reason.

Modules: :mod:`~cosim.campaign.spec` (the TOML file, its lines and values located by
:mod:`~cosim.campaign.spec_values`), :mod:`~cosim.campaign.draws` (what each run draws),
:mod:`~cosim.campaign.plan` (the campaign checked and drawn before any run),
:mod:`~cosim.campaign.task` (one run, on a worker), :mod:`~cosim.campaign.engine` (Dask, the
output folder), :mod:`~cosim.campaign.report` (tables and figures).
"""

from cosim.campaign.engine import CampaignResult, run_campaign
from cosim.campaign.spec import CampaignSpec, load

__all__ = ["CampaignResult", "CampaignSpec", "load", "run_campaign"]
