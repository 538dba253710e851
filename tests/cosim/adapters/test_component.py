"""The ``robust-mpc`` controller component: with the model as plant, and end to end."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from controllers.model import DEFAULT_MODEL
from cosim.adapters.gru_plant import GRUPlant
from cosim.adapters.robust_mpc import RobustMPCController
from cosim.core import scenario
from cosim.core.errors import CosimError
from cosim.core.master import Master
from tests.fourtank_problem import FOURTANK

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def ctrl():
    return RobustMPCController()


def write_scenario(tmp_path, rows):
    path = tmp_path / "sc.csv"
    path.write_text("time,ref.h1,ref.h2\n" + "\n".join(rows) + "\n")
    return scenario.load(path)


def test_interface(ctrl):
    assert ctrl.direct_feedthrough is True
    assert ctrl.sample_time == ctrl.mpc.model.Ts == 25.0
    assert ctrl.bounds == FOURTANK.bounds()
    assert [s.name for s in ctrl.inputs] == ["h1", "h2", "ref.h1", "ref.h2"]
    assert [s.name for s in ctrl.outputs] == ["qa", "qb"]
    # the certificate the controller runs on passes its hypotheses at a nominal set-point
    assert ctrl.mpc.cert.ok(ctrl.mpc.model.normalize_y(np.array([1.0, 1.0])))


def test_short_closed_loop_with_model_as_plant(ctrl, tmp_path):
    sc = write_scenario(tmp_path, ["0,0.8,0.8", "250,1.0,0.9", "1000,,"])
    plant = GRUPlant(ctrl.mpc.model, y0=np.array([0.8, 0.8]))
    res = Master(plant, ctrl, sc).run()
    assert res.status == "ok", res.reason
    cols = res.columns
    rows = np.array(res.rows)
    for name, (lo, hi) in FOURTANK.bounds().items():
        col = next(c for c in cols if c.endswith("." + name) and not c.startswith("ref"))
        v = rows[:, cols.index(col)]
        assert np.all(v >= lo - 1e-12) and np.all(v <= hi + 1e-12), name
    diag = ctrl.diagnostics()
    for key in ("solve_ms", "iterations", "status", "cost", "alpha", "e_o",
                "x_hat_error_bound", "active_constraints", "fallback"):
        assert key in diag and np.isfinite(diag[key]), key
    s = ctrl.summary()
    assert s["steps"] == len(res.rows)
    assert s["setpoint_changes"] == 2 and s["setpoint_rejected_steps"] == 0
    assert s["solve_ms_median"] > 0 and s["fallbacks"] <= s["failures"]
    # the level moved towards the new set-point (the model is the plant: small offset only)
    h1 = rows[:, cols.index(next(c for c in cols if c.endswith(".h1")
                             and not c.startswith("ref")))]
    assert abs(h1[-1] - 1.0) < 0.05


def test_inadmissible_setpoint_is_held_and_reported(tmp_path):
    """The paper's law keeps the last admissible set-point; the default tracking law refuses
    nothing and steers towards the closest admissible steady state instead."""
    sc = write_scenario(tmp_path, ["0,0.8,0.8", "100,1.98,0.8", "200,,"])
    ctrl = RobustMPCController(law="paper")
    plant = GRUPlant(ctrl.mpc.model, y0=np.array([0.8, 0.8]))
    res = Master(plant, ctrl, sc).run()
    assert res.status == "ok", res.reason
    s = ctrl.summary()
    assert s["setpoint_rejected_steps"] >= 4  # t = 100, 125, 150, 175 (and 200)
    assert "Assumption 1" in s["setpoint_rejections"][0]
    assert ctrl.diagnostics()["setpoint_rejected"] == 1.0
    assert ctrl.diagnostics()["y_model_h1"] == pytest.approx(0.8)
    tracking = RobustMPCController()
    res = Master(GRUPlant(tracking.mpc.model, y0=np.array([0.8, 0.8])), tracking, sc).run()
    assert res.status == "ok", res.reason
    assert tracking.summary()["setpoint_rejected_steps"] == 0
    assert 0.8 < tracking.diagnostics()["y_model_h1"] < 1.98   # the closest admissible one


def test_inadmissible_first_setpoint_is_an_error(tmp_path):
    ctrl = RobustMPCController(law="paper")
    ctrl.set_inputs({"h1": 0.8, "h2": 0.8, "ref.h1": 1.99, "ref.h2": 0.8})
    with pytest.raises(CosimError, match="Assumption 1"):
        ctrl.step(0.0, 25.0)


@pytest.mark.slow
def test_cosim_run_paper_scenario_end_to_end(tmp_path, fmu_paths):
    assert fmu_paths[0].exists()  # built by the session fixture (cosim build-fmu)
    out = tmp_path / "paper"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run",
                           str(ROOT / "scenarios" / "paper_steps.csv"), "--controller",
                           "robust-mpc", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok"
    for name, v in summary["kpis"]["violations"].items():
        assert v["count"] == 0, name
    cs = summary["controller_summary"]
    assert cs["steps"] >= 1600
    assert cs["setpoint_rejected_steps"] == 0


def test_options_outside_the_theorem(tmp_path):
    """setpoint_rate ramps the FHOCP set-point; offset_free shifts it by the filtered y − ŷ."""
    sc = write_scenario(tmp_path, ["0,0.8,0.8", "100,1.0,0.8", "400,,"])
    ctrl = RobustMPCController(law="paper", setpoint_rate=0.02, offset_free=True)
    plant = GRUPlant(ctrl.mpc.model, y0=np.array([0.8, 0.8]), w_y_max=0.02, seed=2)
    res = Master(plant, ctrl, sc).run()
    assert res.status == "ok", res.reason
    cols, rows = res.columns, np.array(res.rows)
    y_model = rows[:, cols.index("ctrl.y_model_h1")]
    steps = np.diff(y_model[(rows[:, 0] >= 100)])
    assert np.max(steps) <= 0.02 + 0.01  # ramp of 0.02 m/sample plus the offset correction
    assert ctrl.summary()["setpoint_rate"] == 0.02 and ctrl.summary()["offset_free"] is True


def _large_step_run(tmp_path, **kw):
    sc = write_scenario(tmp_path, ["0,0.6,0.6", "100,1.4,1.4", "1250,,"])
    ctrl = RobustMPCController(**kw)
    plant = GRUPlant(ctrl.mpc.model, y0=np.array([0.6, 0.6]))
    res = Master(plant, ctrl, sc).run()
    assert res.status == "ok", res.reason
    return ctrl, res


@pytest.mark.slow
def test_governor_keeps_fhocp_feasible_after_large_step(tmp_path):
    """0.6 → 1.4 m on both tanks with the model as plant: the paper's controller (no
    governor) cannot reach the new terminal set in N steps and falls back to infeasible
    shifted candidates; with the governor every applied sequence is feasible for the
    governed set-point, there are fewer fallbacks, the constraints hold, the governed
    set-point reaches the requested one, and the run is deterministic."""
    paper, _ = _large_step_run(tmp_path, law="paper", governor=False)
    gov, res = _large_step_run(tmp_path, law="paper")
    sp, sg = paper.summary(), gov.summary()
    assert sp["fallback_candidates_infeasible"] > 0
    assert sg["fallback_candidates_infeasible"] == 0
    assert sg["fallbacks"] < sp["fallbacks"]
    assert sg["fallbacks"] <= 2
    assert sg["governor_steps"] > 0
    cols, rows = res.columns, np.array(res.rows)
    assert "ctrl.solve_ms" not in cols  # wall clock: timings.csv, not results.csv
    h = rows[:, [cols.index("plant.h1"), cols.index("plant.h2")]]
    assert np.all((h >= 0.0) & (h <= 2.0))
    assert rows[-1, cols.index("ctrl.y_model_h1")] == pytest.approx(1.4)
    assert rows[-1, cols.index("ctrl.governor_lambda")] == 1.0
    assert np.max(np.abs(h[-1] - 1.4)) < 0.05
    _, again = _large_step_run(tmp_path, law="paper")
    assert again.columns == res.columns and again.rows == res.rows


@pytest.mark.parametrize(("options", "words"), [
    ({"offset_filter": 2}, "offset_filter=2: expected a number in (0, 1]"),
    ({"offset_filter": "x"}, "offset_filter='x'"),
    ({"law": "paper", "setpoint_rate": 0}, "setpoint_rate=0: expected a positive number"),
    ({"law": "paper", "setpoint_rate": -1.0}, "setpoint_rate=-1.0"),
    ({"law": "paper", "offset_free": "no"}, "offset_free='no': expected true or false"),
    ({"law": "paper", "governor": 1}, "governor=1: expected true or false"),
    ({"ipopt_options": 3}, "ipopt_options=3: expected an object"),
    ({"name": 3}, "name=3: expected a non-empty string"),
    ({"solver": "fatrop"}, "solver='fatrop': expected \"sqp\" or \"ipopt\""),
    ({"du_weight": -1}, "du_weight=-1: expected a non-negative number or an object"),
    ({"du_weight": "x"}, "du_weight='x'"),
    ({"du_weight": True}, "du_weight=True"),
    ({"du_weight": {"qa": -2}}, "du_weight={'qa': -2}"),
    ({"du_weight": {"qc": 1}}, "option du_weight: unknown input 'qc' (inputs: qa, qb)"),
    ({"Q": "inputs"}, "option Q='inputs': expected a number, a 20x20 matrix or \"outputs\""),
])
def test_bad_options_are_one_line_errors(options: dict, words: str) -> None:
    with pytest.raises(CosimError) as info:
        RobustMPCController(**options)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_output_stage_cost() -> None:
    """Q="outputs": U_oᵀ U_o + 10⁻³ I, positive definite, and the certificate's terminal
    weight s follows it (s = n λmax(Q) / (1 − ρ_s²), as for any Q)."""
    default = RobustMPCController(law="paper")
    c = RobustMPCController(law="paper", Q="outputs")
    Uo = c.mpc.model.params["U_o"]
    assert np.allclose(c.mpc.cert.Q, Uo.T @ Uo + 1e-3 * np.eye(c.mpc.model.n))
    assert np.min(np.linalg.eigvalsh(c.mpc.cert.Q)) > 0 and c.summary()["options"]["Q"] == "outputs"
    ratio = (np.max(np.linalg.eigvalsh(c.mpc.cert.Q))
             / np.max(np.linalg.eigvalsh(default.mpc.cert.Q)))
    assert c.mpc.cert.s == pytest.approx(ratio * default.mpc.cert.s, rel=1e-9)


def test_solver_option_selects_the_nlp_solver() -> None:
    assert RobustMPCController().mpc.fhocp.solver == "sqp"
    assert RobustMPCController(solver="ipopt").mpc.fhocp.solver == "ipopt"


def test_the_observer_uses_the_fhocp_kernel() -> None:
    """The observer's update runs in the FHOCP's compiled kernel when there is one, in numpy
    with kernel="numpy"; the summary says which."""
    c = RobustMPCController()
    assert c.mpc.observer.kernel is c.mpc.fhocp.kernel
    assert c.summary()["kernel"] == ("compiled" if c.mpc.fhocp.kernel is not None else "numpy")
    n = RobustMPCController(kernel="numpy")
    assert n.mpc.observer.kernel is None and n.summary()["kernel"] == "numpy"


def test_gru_plant_start_parameters() -> None:
    from controllers.equilibrium import equilibrium_for_output
    from controllers.model import GRUModel

    model = GRUModel.load(DEFAULT_MODEL)
    plant = GRUPlant(model)
    assert {"h1_start", "h2_start", "w_y_max", "seed", "dx_1", f"dx_{model.n}"} <= \
        plant.settable(True)
    assert plant.settable(False) == {"qa", "qb"}
    plant.set_parameter("h1_start", 0.9)
    plant.set_parameter("dx_2", 0.01)
    plant.set_parameter("w_y_max", 0.05)
    plant.setup(0.0)
    x_eq, _ = equilibrium_for_output(model, model.normalize_y(np.array([0.9, 1.0])))
    assert np.allclose(plant.x - x_eq, np.eye(model.n)[1] * 0.01)
    outs = [plant.get_outputs()["h1"] for _ in range(3) if not plant.step(0.0, 25.0)]
    assert len(set(outs)) == 3  # the perturbation is drawn every step
    with pytest.raises(CosimError, match="no plant parameter 'dx_99'"):
        plant.set_parameter("dx_99", 0.0)
    with pytest.raises(CosimError, match=r"'w_y_max' = -1\.0 is negative"):
        plant.set_parameter("w_y_max", -1.0)


def test_reused_controller_gives_the_results_of_a_new_one() -> None:
    """A campaign worker reuses one controller for many runs: setup() restarts it exactly."""
    from cosim.core.scenario import load

    ctrl = RobustMPCController()
    sc = load(ROOT / "scenarios" / "paper_steps.csv").with_changes(stop_time=5000.0)

    def rows(c: RobustMPCController) -> np.ndarray:
        return np.asarray(Master(GRUPlant(c.mpc.model, y0=np.array([0.7, 0.7])), c, sc).run().rows)

    first, again, fresh = rows(ctrl), rows(ctrl), rows(RobustMPCController())
    assert np.array_equal(first, again, equal_nan=True)
    assert np.array_equal(first, fresh, equal_nan=True)


# -- problems other than the four tanks: any m inputs, p outputs, Ts ------------------------------
def _certified_model_file(tmp_path: Path, model, inputs: list) -> tuple[Path, list]:
    """Save ``model`` with w̄_y = 0.01 and the observer gains of the largest θ passing every
    hypothesis at the equilibrium outputs of ``inputs`` (normalised), which it returns in
    the problem's units."""
    from controllers.certification import gain_design
    from controllers.equilibrium import equilibrium_output

    model.w_y_bar = 0.01
    ys = [equilibrium_output(model.params, np.asarray(u, dtype=float))[1] for u in inputs]
    theta, cert = gain_design.choose_gain_scale(model, ys, N=15)
    assert theta is not None, "test design: the hypotheses must hold"
    model.L_z, model.L_r = cert.L_z, cert.L_r
    path = tmp_path / f"{model.problem.name}.json"
    model.save(path)
    return path, [model.denormalize_y(y) for y in ys]


def _steps_scenario(tmp_path: Path, model, setpoints: list, samples: int):
    """Set-point steps every ``samples`` samples of the problem's Ts, one ``ref.<output>``
    column each."""
    Ts, names = model.Ts, model.output_names
    rows = [f"{k * samples * Ts:g}," + ",".join(f"{float(v)!r}" for v in y)
            for k, y in enumerate(setpoints)]
    rows.append(f"{len(setpoints) * samples * Ts:g}" + "," * len(names))
    path = tmp_path / "steps.csv"
    path.write_text("time," + ",".join(f"ref.{n}" for n in names) + "\n"
                    + "\n".join(rows) + "\n")
    return scenario.load(path)


CASES = {  # name: (m, p, other problem, seed, inputs of the set-points, normalised)
    "siso": (1, 1, False, 1, [[0.0], [0.5], [-0.5]]),
    "3-inputs-2-outputs": (3, 2, False, 2, [[0.0] * 3, [0.4, -0.3, 0.2], [-0.4, 0.2, -0.3]]),
    "2x2-cstr-Ts-15": (2, 2, True, 3, [[0.0, 0.0], [0.5, -0.4], [-0.4, 0.3]]),
}


@pytest.mark.parametrize("law", ["tracking", "paper"])
@pytest.mark.parametrize("case", list(CASES))
def test_closed_loop_on_other_problems(case: str, law: str, tmp_path: Path) -> None:
    """The GRU model as the plant, set-point steps of its own problem, under either law: each
    tracked to 1e-3 of its output's half-width (normalised) within 50 samples, every input
    inside its box, every output inside its constraint, no set-point refused and no
    fallback; results and summary named by the problem's signals and problem. The model's
    set-point is the requested one (the paper's law) or within 1e-3 of it (the tracking
    law's artificial steady output, which is the requested one up to the solver's
    tolerance)."""
    from tests.controllers.random_gru import other_problem, random_gru_model

    m, p, other, seed, inputs = CASES[case]
    model = random_gru_model(seed, n=10, m=m, p=p,
                             problem=other_problem() if other else None)
    path, setpoints = _certified_model_file(tmp_path, model, inputs)
    samples = 50
    sc = _steps_scenario(tmp_path, model, setpoints, samples)
    ctrl = RobustMPCController(model=path, law=law)
    pr = ctrl.problem
    assert (pr.m, pr.p) == (m, p) and ctrl.sample_time == pr.Ts == model.Ts
    assert [s.name for s in ctrl.outputs] == list(pr.input_names)
    res = Master(GRUPlant(model, y0=setpoints[0]), ctrl, sc).run()
    assert res.status == "ok", res.reason
    cols, rows = res.columns, np.array(res.rows)
    for c in pr.inputs:
        u = rows[:, cols.index(f"ctrl.{c.name}")]
        assert np.all((u >= c.min) & (u <= c.max)), c.name
    for c in pr.outputs:
        y = rows[:, cols.index(f"plant.{c.name}")]
        assert np.all((y >= c.min) & (y <= c.max)), c.name
    for k, ybar in enumerate(setpoints):
        end = (k + 1) * samples - 1     # the last sample of set-point k
        for j, c in enumerate(pr.outputs):
            err = abs(rows[end, cols.index(f"plant.{c.name}")] - ybar[j])
            assert err <= 1e-3 * abs(model.y_scale[j]), (k, c.name, err)
            y_model = rows[end, cols.index(f"ctrl.y_model_{c.name}")]
            if law == "paper":
                assert y_model == ybar[j]
            else:
                assert abs(y_model - ybar[j]) <= 1e-3 * abs(model.y_scale[j])
    s = ctrl.summary()
    assert s["problem"] == pr.name and s["kernel"] in ("compiled", "numpy")
    assert s["setpoint_rejected_steps"] == 0 and s["fallbacks"] == 0
    assert s["setpoint_changes"] == len(setpoints)


def test_more_outputs_than_inputs_refuses_setpoints_off_the_curve(tmp_path: Path) -> None:
    """One input, two outputs: the reachable set-points are a curve. Under the paper's law a
    first set-point off it stops the run with one line naming the closest reachable output; a
    later one is refused (the controller keeps the last set-point, counts and names it) and
    the next reachable one is tracked. The tracking law refuses nothing: it steers to the
    closest reachable output."""
    from controllers.equilibrium import equilibrium_for_output
    from controllers.gru import output
    from tests.controllers.random_gru import random_gru_model

    model = random_gru_model(4, n=10, m=1, p=2)
    path, (y0, y1) = _certified_model_file(tmp_path, model, [[0.0], [0.4]])
    off = 0.5 * (y0 + y1) + np.array([0.05, -0.05])
    xb, _ = equilibrium_for_output(model, model.normalize_y(off))
    closest = model.denormalize_y(output(model.params, xb))
    words = (f"not reachable with inputs inside the saturation box (‖u‖∞ ≤ 1) (2 outputs, 1 "
             f"input: only the model's 1-dimensional surface of equilibrium outputs is "
             f"reachable); the closest reachable equilibrium output is "
             f"h1={closest[0]:.4g} m, h2={closest[1]:.4g} m")
    ctrl = RobustMPCController(model=path, law="paper")
    res = Master(GRUPlant(model, y0=y0), ctrl,
                 _steps_scenario(tmp_path, model, [off, y1], 5)).run()
    assert res.status == "failed" and "t=0 s" in res.reason and words in res.reason
    assert "\n" not in res.reason
    res = Master(GRUPlant(model, y0=y0), ctrl,
                 _steps_scenario(tmp_path, model, [y0, off, y1], 40)).run()
    assert res.status == "ok", res.reason
    s = ctrl.summary()
    assert s["setpoint_rejected_steps"] == 40 and len(s["setpoint_rejections"]) == 1
    assert s["setpoint_rejections"][0].startswith("t=1000 s: ")
    assert words in s["setpoint_rejections"][0]
    cols, rows = res.columns, np.array(res.rows)
    held = rows[40:80, cols.index("ctrl.y_model_h1")]
    assert np.all(held == y0[0]) and np.all(rows[40:80, cols.index("ctrl.setpoint_rejected")])
    h = rows[-1, [cols.index("plant.h1"), cols.index("plant.h2")]]
    assert np.max(np.abs(model.normalize_y(h) - model.normalize_y(y1))) < 1e-3
    # the default tracking law starts on the same set-point and steers to the closest one
    tracking = RobustMPCController(model=path)
    res = Master(GRUPlant(model, y0=y0), tracking,
                 _steps_scenario(tmp_path, model, [off, y1], 40)).run()
    assert res.status == "ok", res.reason
    assert tracking.summary()["setpoint_rejected_steps"] == 0
    cols, rows = res.columns, np.array(res.rows)
    h = rows[39, [cols.index("plant.h1"), cols.index("plant.h2")]]
    assert np.max(np.abs(model.normalize_y(h) - model.normalize_y(closest))) < 1e-2, (h, closest)


def test_build_kernel_for_any_problem(tmp_path: Path, capsys) -> None:
    """cosim build-kernel --model FILE [--problem P]: the model's own problem, named in the
    output with its numbers of signals; a contradicting --problem is exit 2 naming both."""
    from cosim.cli import main
    from tests.controllers.random_gru import random_gru_model

    model = random_gru_model(2, n=10, m=3, p=2)
    path, _ = _certified_model_file(tmp_path, model, [[0.0] * 3])
    assert main(["build-kernel", "--model", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"compiled kernel for {path}, problem 'test3x2' (n=10, m=3, p=2, N=80)" in out
    from tests.fourtank_problem import PATH

    assert main(["build-kernel", "--model", str(path), "--problem", str(PATH)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--problem {PATH} contradicts the problem of {path}" in err
    assert "'test3x2'" in err and "'fourtank'" in err


def test_cosim_run_on_another_problem_names_it(tmp_path: Path) -> None:
    """cosim run with the GRU model of the CSTR-like problem as plant and controller model:
    results.csv names the problem's signals, summary.json the problem."""
    from cosim.cli import main
    from tests.controllers.random_gru import other_problem, random_gru_model

    model = random_gru_model(3, n=10, problem=other_problem())
    path, setpoints = _certified_model_file(tmp_path, model, [[0.0, 0.0], [0.5, -0.4]])
    _steps_scenario(tmp_path, model, setpoints, 10)
    out = tmp_path / "run"
    assert main(["run", str(tmp_path / "steps.csv"), "--plant", f"model:{path}", "--model",
                 str(path), "--out", str(out), "--quiet", "--no-figure"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["step_size"] == 15.0
    assert summary["controller_summary"]["problem"] == "cstr"
    header = [c.strip('"') for c in
              (out / "results.csv").read_text().splitlines()[0].split(",")]
    for name in ("ref.CA", "ref.T", "plant.CA", "plant.T", "ctrl.F", "ctrl.Tc",
                 "ctrl.y_model_CA", "ctrl.y_model_T"):
        assert name in header, name


def test_the_model_as_a_plant_with_an_input_gain_off(ctrl):
    """``gain_<input>``: the plant's gain on one input a factor on its move from where the
    run starts (what ``cosim tune`` checks robustness on); 1 is the model, the others'
    moves unchanged."""
    model = ctrl.mpc.model

    def levels(gains: dict[str, float], qa: float) -> np.ndarray:
        plant = GRUPlant(model, y0=np.array([0.8, 0.8]))
        for name, g in gains.items():
            plant.set_parameter(f"gain_{name}", g)
        plant.setup(0.0)
        start = model.denormalize_u(plant.u)
        plant.set_inputs({"qa": start[0] * (1.0 + qa)})
        for _ in range(40):
            plant.step(0.0, model.Ts)
        return model.normalize_y(np.array(list(plant.get_outputs().values())))

    rest = levels({}, 0.0)
    assert np.allclose(levels({"qa": 1.7}, 0.0), rest)          # no move: no effect
    base = levels({}, 0.1) - rest
    assert np.allclose(levels({"qa": 1.0, "qb": 3.0}, 0.1) - rest, base)
    # gain 1.5 on qa: the levels as the model's for 1.5 x the move
    assert np.allclose(levels({"qa": 1.5}, 0.1) - rest, levels({}, 0.15) - rest, atol=1e-12)
    assert "gain_qb" in GRUPlant(model).settable(at_start=True)
    with pytest.raises(CosimError, match="no plant parameter 'gain_q'"):
        GRUPlant(model).set_parameter("gain_q", 1.0)
