"""Certificates, admissible ranges and default set-points for any numbers of inputs m and
outputs p (controllers.certification.certificates, controllers.certification.gain_design): one,
two, three, five outputs; fewer and more inputs than outputs."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.certification import certificates as certs
from controllers.certification import gain_design
from controllers.certification.output_ranges import admissible_ranges
from controllers.errors import ControllersError
from controllers.gru import output, step
from controllers.problem import Channel, ControlProblem
from tests.controllers.random_gru import random_gru_model


def _box_problem(p: int, lo: float = 280.0, hi: float = 360.0) -> ControlProblem:
    return ControlProblem(name=f"box{p}", Ts=15.0, inputs=(Channel("u", "%", 0.0, 100.0),),
                          outputs=tuple(Channel(f"T{j + 1}", "K", lo + 2 * j, hi - j)
                                        for j in range(p)))


@pytest.mark.parametrize("p", [1, 2, 3, 4, 5])
def test_default_setpoints_are_a_grid_over_the_output_box(p: int) -> None:
    """25, 50 and 75 % of each output's box: 3^p points up to 81 (p ≤ 4), else the middle and
    ±25 % along each output (2p + 1 points); the four-tank's is {0.5, 1.0, 1.5}² m."""
    pr = _box_problem(p)
    pts = gain_design.default_setpoints(pr)
    levels = [[c.min + f * (c.max - c.min) for f in (0.25, 0.5, 0.75)] for c in pr.outputs]
    mid = tuple(lv[1] for lv in levels)
    assert all(len(pt) == p for pt in pts) and len(set(pts)) == len(pts)
    if p <= 4:
        assert len(pts) == 3 ** p
        assert set(pts) == {tuple(pt) for pt in np.array(np.meshgrid(*levels, indexing="ij"))
                            .reshape(p, -1).T.tolist()}
    else:
        assert len(pts) == 2 * p + 1 and pts[0] == mid
        for pt in pts[1:]:
            (j,) = [k for k in range(p) if pt[k] != mid[k]]
            assert pt[j] in (levels[j][0], levels[j][2])
    if p == 1:
        assert pts == [(300.0,), (320.0,), (340.0,)]
    from tests.fourtank_problem import FOURTANK

    assert gain_design.default_setpoints(FOURTANK) == [
        (a, b) for a in (0.5, 1.0, 1.5) for b in (0.5, 1.0, 1.5)]


@pytest.mark.parametrize(("m", "p"), [(1, 1), (3, 2), (1, 2), (2, 3)])
def test_reference_and_admissible_ranges_for_any_numbers_of_signals(m: int, p: int) -> None:
    """Certificate.reference gives an equilibrium with ū of m entries at a reachable
    admissible set-point; admissible_ranges gives one interval per output inside its box, a
    set-point just inside it passes the hypotheses and one just beyond fails them; with p > m
    a set-point inside the ranges but off the surface of equilibrium outputs is refused
    naming the closest reachable output."""
    from controllers.equilibrium import equilibrium_output
    from controllers.errors import UnreachableSetpoint

    model = random_gru_model(6, n=8, m=m, p=p)
    model.w_y_bar = 0.01
    c = certs.compute_certificate(model, N=15)
    ranges = admissible_ranges(c, model)
    assert [r[0] for r in ranges] == list(model.output_names)
    for (name, lo, hi), ch in zip(ranges, model.problem.outputs, strict=True):
        assert lo is not None and hi is not None and ch.min < lo < hi < ch.max, name
    _, y = equilibrium_output(model.params, np.full(m, 0.2))
    ref = c.reference(y)
    assert ref.u_bar.shape == (m,) and ref.x_bar.shape == (8,)
    assert output(model.params, ref.x_bar) == pytest.approx(y, abs=1e-9)
    assert np.max(np.abs(step(model.params, ref.x_bar, ref.u_bar) - ref.x_bar)) < 1e-12
    assert ref.alpha == pytest.approx(c.alpha(y)) and c.ok(y)
    width = model.problem.outputs[-1].max - model.problem.outputs[-1].min
    edge = model.denormalize_y(y)
    for delta, ok in ((-1e-6, True), (1e-6, False)):
        edge[-1] = ranges[-1][2] + delta * width
        assert c.ok(model.normalize_y(edge)) is ok
    with pytest.raises(ControllersError, match=r"recursive feasibility|Assumption 1"):
        c.reference(model.normalize_y(edge))
    if p > m:
        off = y.copy()
        off[-1] += 0.05
        assert c.ok(off)
        with pytest.raises(UnreachableSetpoint, match=r"outputs, .* input.*: only the "
                           r"model's .*closest reachable equilibrium output is"):
            c.reference(off)
