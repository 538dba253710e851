"""Every shipped scenario, with the MPC and the PI baseline (and on the third-party plant),
must reproduce its reference in ``scenarios/references/`` within the default tolerances of
:mod:`cosim.core.compare`."""

from __future__ import annotations

import pytest

from cosim.core.compare import compare, read_table
from tests.regression import regression_cases as rc

CASES = rc.shipped_cases()


def test_scenarios_are_shipped() -> None:
    assert CASES, "no scenarios/*.csv found"


def test_every_reference_belongs_to_a_case() -> None:
    """No stale reference is left behind (a renamed case, a law that changed its name)."""
    stale = {p.name for p in rc.REFERENCES.glob("*.csv")} - {c.reference.name for c in CASES}
    assert not stale, f"scenarios/references: no regression case for {sorted(stale)}"
    # the robust MPC's default law and the paper's law on every scenario and both plants
    mpc = [(c.scenario.stem, c.plant, c.label) for c in CASES if c.controller == "robust-mpc"]
    stems = {c.scenario.stem for c in CASES}
    assert sorted(mpc, key=str) == sorted(
        ((s, plant, label) for s in stems for plant in (None, rc.THIRDPARTY_PLANT)
         for label in (None, "robust-mpc-paper")), key=str)


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_matches_reference(case: rc.Case, regression_runs: dict[str, rc.Run],
                           update_references: bool) -> None:
    reason = rc.controller_available(case.controller)
    if reason is not None:
        pytest.skip(f"controller '{case.controller}' not available: {reason}")
    run = regression_runs[case.id]
    assert run.returncode == 0, f"cosim run failed for {case.id}:\n{run.output}"
    if update_references:
        rc.write_reference(run.results, case.reference)
        return
    if not case.reference.is_file():
        pytest.fail(f"no reference {case.reference.relative_to(rc.ROOT)} for {case.id}; "
                    f"{rc.UPDATE_HINT}")
    reference = read_table(case.reference)
    result = compare(run.results, case.reference,
                     signals=rc.compared_columns(reference.names))
    if not result.passed:
        pytest.fail(f"{case.id} deviates from its reference "
                    f"(if intended, {rc.UPDATE_HINT}):\n{result.report()}", pytrace=False)
