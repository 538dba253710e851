"""Tuning the robust MPC on its model: the cost weights chosen as the PI baseline is tuned.

:func:`tune` runs the robust MPC (its default law, :data:`controllers.laws.DEFAULT`, or the
law asked for) with the weightings of :data:`CANDIDATES`, and the PI baseline tuned from the
same model, in closed loop with the GRU model itself as the plant (``plant = "model:…"``: no
FMU needed) on a set-point scenario (given, else :func:`scenario`: steps between four steady
outputs the model reaches with its inputs inside their box, inside the output box by a
twentieth of it or two of the noise's standard deviations, each held six of its slowest time
constants, with Gaussian sensor noise whose standard deviation is the one ``cosim train``
measured on the data, else the model's measured one-step prediction error, an upper
estimate: a weighting that passes noise on to the inputs loses where the data were noisy).

The plant is never the model: each weighting also runs on the model with one manipulated
input's gain ``1 + gain_uncertainty`` times the model's, then ``1 − gain_uncertainty`` times
(default :data:`GAIN_UNCERTAINTY`, the plant's ``gain_<input>``:
:class:`cosim.adapters.gru_plant.GRUPlant`), ``2 m`` runs more for each weighting within the
TV bound below (the others cannot be chosen), the multiplicative input uncertainty of robust
control, without the sensor noise (the gain's effect alone; the run on the model has the
noise). A weighting that is fast on the model can be unstable on a plant whose gains differ
from it: on the zoo's Shell fractionator (the workshop's gain uncertainty, ``|eps| ≤ 1``)
the default weights left the box in 12 of 20 campaign runs, four of them oscillating across
it, and on its Wood–Berry column (gains within 10 %) xB dipped under its bound in 20 of 20;
the ``moves`` candidates, heavier move suppression, are there for those (docs:
guide/own-plant.md, "The zoo", for what they did). :func:`choose` keeps, among the
weightings whose input total variation is at most ``tv_ratio`` times the PI's (or the
default weights', where they move more: those are always a candidate), those with the fewest
samples outside the output box (over the nominal and the perturbed runs), of them those with
the fewest runs that leave it, and of those the one with the lowest summed IAE over every
run (each output's IAE over its box width); a plant that is not square has no PI baseline,
and the default weights are the reference. ``save=True`` writes the choice into the model
file's problem as its ``[mpc]`` table (:attr:`controllers.problem.ControlProblem.mpc`),
which every later run of the model uses under its own options. ``cosim tune`` is its command
(:mod:`cosim.commands.tune`).
"""

from __future__ import annotations

import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CANDIDATES", "GAIN_UNCERTAINTY", "RHO_HINT", "TuneResult", "choose",
           "faster_contraction", "hint", "perturbed", "scenario", "tune", "within"]

#: The weightings tried (robust-MPC options; ``Q``, ``R``, ``du_weight`` in normalised units).
CANDIDATES: dict[str, dict[str, Any]] = {
    "defaults": {"Q": 1.0, "R": 0.01, "du_weight": 0.05},
    "output cost": {"Q": "outputs", "R": 0.01, "du_weight": 0.05},
    "output cost, light inputs": {"Q": "outputs", "R": 0.001, "du_weight": 0.01},
    "output cost, free inputs": {"Q": "outputs", "R": 0.001, "du_weight": 0.0},
    "smooth moves": {"Q": 1.0, "R": 0.01, "du_weight": 0.5},
    "slow moves": {"Q": 1.0, "R": 0.01, "du_weight": 5.0},
    "slowest moves": {"Q": 1.0, "R": 0.01, "du_weight": 50.0},
}
#: The input-gain uncertainty every weighting is run against (module docstring): each
#: manipulated input's gain times ``1 + GAIN_UNCERTAINTY``, then ``1 − GAIN_UNCERTAINTY``,
#: in turn (a gain larger than the model's is what makes a fast weighting oscillate, a
#: smaller one what makes a slow weighting trail a disturbance out of the box).
GAIN_UNCERTAINTY = 0.5
#: Where the inputs are held for the generated scenario's set-points (fractions of each
#: input's box; input j takes the pattern shifted by j).
PATTERN = (0.3, 0.7, 0.5, 0.2)
#: A contraction rate of the certificate (``rho_s``, ``lem:Vs``) above which a tuning that
#: does not beat the PI points at the training (:func:`hint`).
RHO_HINT = 0.99
#: Hold of each generated set-point: this many of the model's slowest time constants, within
#: these bounds [samples].
HOLD_TIME_CONSTANTS, HOLD_MIN, HOLD_MAX = 6.0, 20, 300
#: Closed-loop steps of a tuning (all runs together) above which ``workers=0`` runs them in
#: worker processes (below, starting the workers costs more than it saves).
WORKER_STEPS = 2000


@dataclass
class TuneResult:
    """What :func:`tune` found.

    Attributes
    ----------
    rows : dict
        Candidate name → ``iae`` and ``tv`` (summed, over the reference's) and ``violations``
        on the model; ``violating_runs`` (of the nominal and perturbed runs),
        ``violations_all`` (their samples outside the box) and ``iae_all`` (summed over
        every run, over the reference's nominal), ``None`` for a
        weighting outside the TV bound (:func:`within`: not run perturbed).
    chosen : str
        The candidate :func:`choose` picked.
    against : {"pi", "defaults"}
        The reference of the ratios: the PI tuned from the model, or (not a square plant)
        the default weights.
    hint : str or None
        What to do when no weighting beats the PI (:func:`hint`).
    law : str or None
        The law tuned (``None``: the default law, :data:`controllers.laws.DEFAULT`).
    scenario : Path or None
        The scenario given (``None``: the generated one).
    saved : bool
        The choice was written into the model file.
    """

    rows: dict[str, dict[str, float]]
    chosen: str
    against: str
    hint: str | None = None
    scenario: Path | None = None
    saved: bool = False
    law: str | None = None

    @property
    def options(self) -> dict[str, Any]:
        """The chosen weighting's robust-MPC options (with its law, when not the
        default)."""
        return {**({"law": self.law} if self.law else {}), **CANDIDATES[self.chosen]}

    def to_dict(self) -> dict[str, Any]:
        """Plain data (``cosim tune --json``)."""
        return {"candidates": self.rows, "chosen": self.chosen, "against": self.against,
                "options": self.options, "hint": self.hint}


def tune(model: str | Path, scenario_file: str | Path | None = None, *,
         tv_ratio: float = 1.2, save: bool = False, progress: bool = False,
         workers: int = 0, law: str | None = None,
         gain_uncertainty: float = GAIN_UNCERTAINTY) -> TuneResult:
    """Tune the robust MPC's weights on ``model`` (module docstring) for its law ``law`` (default:
    :data:`controllers.laws.DEFAULT`), each weighting also run with each manipulated input's
    gain ``1 + gain_uncertainty`` times the model's (0: the model alone). The closed loops
    run in ``workers`` processes (0: one per CPU, at most one per run, unless the runs are
    short: :data:`WORKER_STEPS`; 1: in this process): the same answer either way.
    Interrupted (Ctrl-C), the workers are stopped and the model file is left as it was.

    Raises
    ------
    ParameterError
        A bad ``tv_ratio`` or ``gain_uncertainty``.
    CosimError
        A model file without a control problem, a bad scenario (one line).
    SimulationFailed
        A closed loop failed.
    OutputError
        ``save``: the model file could not be written (it keeps its previous content).
    """
    from controllers import laws
    from controllers.errors import ControllersError
    from controllers.model import GRUModel
    from cosim.core.errors import CosimError, ParameterError

    try:
        law = None if law is None or laws.spec(law).name == laws.DEFAULT else law
    except ControllersError as exc:
        raise CosimError(str(exc)) from None
    if not (isinstance(tv_ratio, int | float) and math.isfinite(tv_ratio) and tv_ratio > 0):
        raise ParameterError("tv_ratio", f" must be a positive number, got {tv_ratio!r}")
    if not (isinstance(gain_uncertainty, int | float) and 0 <= gain_uncertainty < 1):
        raise ParameterError("gain_uncertainty",
                             f" must be a number in [0, 1), got {gain_uncertainty!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ParameterError("workers", f" must be a whole number >= 0, got {workers!r}")
    try:
        gru = GRUModel.load(model)
    except ControllersError as exc:
        raise CosimError(str(exc)) from None
    if gru.problem is None:
        raise CosimError(f"{model}: the model file has no control problem (train it with "
                         "'cosim train --problem')")
    square = gru.problem.m == gru.problem.p
    with tempfile.TemporaryDirectory(prefix="cosim-tune-") as tmp:
        sc = Path(scenario_file) if scenario_file else scenario(gru, Path(tmp) / "steps.csv")
        steps = _steps(sc, gru.problem.Ts)   # the scenario checked before it is copied
        run = {"model": model, "progress": progress, "workers": workers, "steps": steps,
               "law": law or laws.DEFAULT}
        results = _closed_loops(list(CANDIDATES), {"": sc}, square, **run)
        base = results.pop("pi") if square else results["defaults"][""]
        gains = perturbed(sc, gru.problem.input_names, gain_uncertainty, Path(tmp))
        if gains:   # only the weightings the rule may choose: within the TV bound
            nominal = {n: _row(r, base) for n, r in results.items()}
            more = _closed_loops(within(nominal, tv_ratio), gains, False, **run, desc="gains")
            for name, runs in more.items():
                results[name].update(runs)
    rows = {n: _row(r, base, 1 + len(gains)) for n, r in results.items()}
    best = choose(rows, tv_ratio)
    result = TuneResult(rows, best, "pi" if square else "defaults",
                        hint(gru, rows, best, law or laws.DEFAULT) if square else None,
                        Path(scenario_file) if scenario_file else None, law=law)
    if save:
        _save(Path(model), gru, result.options)
        result.saved = True
    return result


def _row(runs: dict[str, dict[str, float]], base: dict[str, float], plants: int = 1
         ) -> dict[str, Any]:
    """A candidate's row of the table from its runs (``""``: on the model; the others
    perturbed) against the reference's run on the model; ``violating_runs``,
    ``violations_all`` (the samples outside the box over every run) and ``iae_all`` ``None``
    when it did not run on all ``plants`` (outside the TV bound)."""
    nominal, done = runs[""], len(runs) == plants
    return {"iae": nominal["iae"] / base["iae"],
            "tv": nominal["tv"] / base["tv"] if base["tv"] else 0.0,
            "violations": nominal["violations"],
            "violating_runs": sum(1 for r in runs.values() if r["violations"]) if done else None,
            "violations_all": sum(r["violations"] for r in runs.values()) if done else None,
            "iae_all": sum(r["iae"] for r in runs.values()) / base["iae"] if done else None}


def perturbed(sc: Path, inputs: tuple[str, ...] | list[str], uncertainty: float,
              folder: Path) -> dict[str, Path]:
    """The scenario ``sc`` once per perturbed plant (module docstring), written into
    ``folder``: ``gain_<input>`` at ``1 + uncertainty`` in its first row, the sensors'
    noise off (none when ``uncertainty`` is 0)."""
    import csv

    from cosim.core.csvio import CsvReader
    from cosim.core.scenario import SCENARIO_WORDING

    if not uncertainty:
        return {}
    with CsvReader(sc, SCENARIO_WORDING, encoding="utf-8-sig", whole_file=True) as f:
        header = f.header()
        rows = [cells for _, cells in f.rows(len(header))]
    first = ["0" if c.strip().startswith("sensor.") and c.strip().endswith(".noise") else v
             for c, v in zip(header, rows[0], strict=True)]   # no noise: the gain alone
    out = {}
    for gain in (1.0 + uncertainty, 1.0 - uncertainty):
        for name in inputs:
            key = f"gain_{name}={gain:g}"
            out[key] = folder / f"{len(out)}.csv"
            with out[key].open("w", newline="", encoding="utf-8") as fh:
                csv.writer(fh, lineterminator="\n").writerows(
                    [[*header, f"plant.gain_{name}"], [*first, f"{gain:g}"],
                     *([*r, ""] for r in rows[1:])])
    return out


def _steps(sc: Path, ts: float) -> int:
    """The closed-loop steps of scenario ``sc`` at sample time ``ts`` (a bad scenario: one
    line, :class:`cosim.core.errors.CosimError`)."""
    from cosim.core import scenario as scenario_mod
    from cosim.core.master import communication_times

    loaded = scenario_mod.load(sc)
    return len(communication_times(loaded.start_time, loaded.stop_time, ts)) - 1


def _closed_loops(names: list[str], plants: dict[str, Path], pi: bool, *,
                  model: str | Path, progress: bool, workers: int, steps: int, law: str,
                  desc: str = "tune") -> dict[str, Any]:
    """:func:`_score` of the PI on the model (``pi``; ``plants[""]``) and of the candidates
    ``names`` on each of ``plants`` (perturbation → its scenario of ``steps`` steps; ``""``:
    the model's), by candidate and plant: in ``workers`` spawned processes (0: one per CPU,
    at most one per run, when the runs have more than :data:`WORKER_STEPS` steps together,
    else 1; 1: in this process), one progress bar (``desc``) over all their steps."""
    import os

    from tqdm import tqdm

    jobs = [("pi", "", str(model), str(plants[""]), None)] if pi else []
    jobs += [(name, key, str(model), str(sc), {"law": law, **CANDIDATES[name]})
             for name in names for key, sc in plants.items()]
    if not workers:   # a worker takes about a second to start: not worth it for short runs
        workers = (min(len(jobs), os.cpu_count() or 1) if steps * len(jobs) > WORKER_STEPS
                   else 1)
    bar = tqdm(total=steps * len(jobs), desc=desc, unit="step", file=sys.stderr,
               disable=not progress, dynamic_ncols=True, mininterval=0.5)
    done = [0] * len(jobs)

    def tick(index: int, k: int) -> None:
        bar.update(k - done[index])
        done[index] = k

    try:
        if workers <= 1:
            scores = [_closed_loop(job, lambda k, i=i: tick(i, k)) for i, job in enumerate(jobs)]
        else:
            from controllers.workers import map_in_workers

            scores = map_in_workers(_closed_loop, jobs, workers, tick)
    finally:
        bar.close()
    out: dict[str, Any] = {}
    for (name, key, *_), score in zip(jobs, scores, strict=True):
        if name == "pi":
            out[name] = score
        else:
            out.setdefault(name, {})[key] = score
    return out


def _closed_loop(job: tuple[str, str, str, str, Any], tick: Any = None) -> dict[str, float]:
    """One tuning run (the PI when ``options`` is ``None``), scored; a run that ended
    degraded (its controller did not serve a tenth of the steps) scores an infinite IAE and
    input motion, so that it is never chosen."""
    import cosim
    from cosim.core.errors import SimulationFailed

    name, key, model, sc, options = job
    controller = "pi" if options is None else "robust-mpc"
    opts = dict(options) if options is not None else {}
    out = cosim.run(sc, plant=f"model:{model}", controller=controller, model=model,
                    options=opts, seed=0, on_step=tick)
    if out.status == "degraded":   # not a candidate: its controller did not serve
        return {"iae": math.inf, "tv": math.inf, "violations": 0}
    if out.status != "ok":
        where = f" (plant {key})" if key else ""
        raise SimulationFailed(f"{name}{where}: the run {out.status}: {out.reason}")
    return _score(out.summary)


def scenario(model: Any, path: Path) -> Path:
    """Write the generated scenario (module docstring) of ``model`` to ``path``."""
    from controllers.equilibrium import jacobians

    problem, params = model.problem, model.params
    lo, hi = np.array(problem.output_bounds).T
    noise = _noise(model)
    # the set-points inside the box by a twentieth of it, or by two of the noise's standard
    # deviations where the sensors are noisier: a set-point where the noise alone crosses
    # the bound scores every weighting by its violations, none by its control
    inset = np.minimum(np.maximum(0.05 * (hi - lo), 2.0 * noise), 0.25 * (hi - lo))
    targets, slowest = [], 0.0
    for k in range(len(PATTERN)):
        u = np.array([c.min + PATTERN[(k + j) % len(PATTERN)] * (c.max - c.min)
                      for j, c in enumerate(problem.inputs)]
                     + [0.5 * (c.min + c.max) for c in problem.disturbances])
        un, x, y = _reachable(model, u, lo + inset, hi - inset)
        rho = float(np.max(np.abs(np.linalg.eigvals(jacobians(params, x, un)[0]))))
        slowest = max(slowest, -1.0 / math.log(min(max(rho, 1e-12), 1.0 - 1e-12)))
        targets.append(np.clip(y, lo + inset, hi - inset))
    hold = int(min(max(math.ceil(HOLD_TIME_CONSTANTS * slowest), HOLD_MIN), HOLD_MAX))
    names = problem.output_names
    header = ["time", *(f"ref.{o}" for o in names), *(f"sensor.{o}.noise" for o in names)]
    rows = [",".join(header)]
    for k, y in enumerate(targets):
        first = [f"{v:.6g}" for v in noise] if k == 0 else [""] * len(names)
        rows.append(",".join([f"{k * hold * problem.Ts:g}", *(f"{v:.6g}" for v in y),
                              *first]))
    rows.append(",".join([f"{len(targets) * hold * problem.Ts:g}"] + [""] * (2 * len(names))))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def _reachable(model: Any, u: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               halvings: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inputs ``u`` (physical; the measured disturbances last, left where they are)
    drawn toward the middle of the input box until the model's steady output lies in
    ``[lo, hi]``, by bisection on the fraction of the way kept: a set-point the model
    reaches with its inputs inside their box, where clipping an output outside the box could
    ask for one it cannot reach. Returns the normalised inputs, the steady state and its
    output (physical); the middle of the box where no fraction puts the output inside."""
    from controllers.equilibrium import equilibrium_output

    mid = u.copy()
    mid[:model.m_u] = [0.5 * (c.min + c.max) for c in model.problem.inputs]

    def at(fraction: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        un = model.normalize_u(mid + fraction * (u - mid))
        x, y = equilibrium_output(model.params, un)
        return un, x, model.denormalize_y(y)

    def inside_box(point: tuple[np.ndarray, np.ndarray, np.ndarray]) -> bool:
        return bool(np.all((point[2] >= lo) & (point[2] <= hi)))

    best = at(1.0)
    if inside_box(best):
        return best
    inside, outside, best = 0.0, 1.0, at(0.0)
    for _ in range(halvings):
        fraction = 0.5 * (inside + outside)
        trial = at(fraction)
        if inside_box(trial):
            inside, best = fraction, trial
        else:
            outside = fraction
    return best


def _noise(model: Any) -> np.ndarray:
    """Sensor noise std per output [its unit]: the one ``cosim train`` measured on the free
    run's residual (``training.prediction_error.sensor_noise``,
    :func:`controllers.certification.prediction_error.offset_filter`), else the measured
    one-step prediction error (its 95th percentile), else ``w̄_y``, else none: the last two
    upper estimates, model error taken for noise (module docstring)."""
    measured = ((model.training or {}).get("prediction_error") or {}).get("sensor_noise")
    if measured:
        return np.array([float(measured[n]) for n in model.problem.output_names])
    profile = model.prediction_error
    if profile is not None and len(profile) > 1:
        err = np.asarray(profile[1], dtype=float)
    elif model.w_y_bar is not None:
        err = np.full(model.p, float(model.w_y_bar))
    else:
        err = np.zeros(model.p)
    return err * np.abs(np.asarray(model.y_scale, dtype=float))


def _score(summary: dict[str, Any]) -> dict[str, float]:
    """Summed IAE and input TV (:func:`cosim.core.kpis.summed`: each over its box width) and
    the violations of a run's summary."""
    from cosim.core.kpis import summed

    return {"iae": summed(summary, "iae"), "tv": summed(summary, "tv"),
            "violations": sum(v["count"] for v in summary["kpis"]["violations"].values())}


def within(rows: dict[str, dict[str, Any]], tv_ratio: float) -> list[str]:
    """The candidates of ``rows`` whose input motion (``tv``, over the reference's) is at most
    ``tv_ratio``, or the defaults' where that is more (:func:`choose`)."""
    bound = max(tv_ratio, rows["defaults"]["tv"] if "defaults" in rows else 0.0)
    return [n for n, r in rows.items() if r["tv"] <= bound]


def choose(rows: dict[str, dict[str, Any]], tv_ratio: float) -> str:
    """The candidate of ``rows`` (name → ratios to the PI: ``iae``, ``tv`` and
    ``violations`` on the model, ``violating_runs``, ``violations_all`` and ``iae_all`` over
    every run; the last three default to the first's) within the TV bound (``tv_ratio``, or
    the defaults' input motion where that is more: the default weights are always a
    candidate, and a weighting that moves the inputs less than they do is too): of those
    with the fewest samples outside the box over every run (where every weighting leaves it
    somewhere: the one that stays out the least), of them those with the fewest violating
    runs, and of those the lowest ``iae_all``; ``"defaults"`` when none is within the
    bound."""
    ok = within(rows, tv_ratio)
    if not ok:
        return "defaults"

    def runs(n: str) -> float:
        return rows[n].get("violating_runs", float(rows[n]["violations"] > 0))

    def outside(n: str) -> float:
        return rows[n].get("violations_all", rows[n]["violations"])

    return min(ok, key=lambda n: (outside(n), runs(n), rows[n].get("iae_all", rows[n]["iae"])))


def hint(model: Any, rows: dict[str, dict[str, float]], best: str,
         law: str | None = None) -> str | None:
    """What to do when no weighting beats the PI on the model (``None`` when one does): with
    a slow certified contraction, the terminal weight ``s = n λ_max(Q) / (1 − ρ_s²)``
    (``eq:definition_s``) makes every horizon's end costly, and only a model trained to
    contract faster lowers it (docs: design/tracking.md, "Other plants")."""
    if rows[best]["iae"] < 1.0:
        return None
    from controllers.certification.certificates import compute_certificate
    from controllers.disturbances import condition
    from controllers.mpc_options import MPCOptions, design_arguments

    text = f"no weighting beats the PI on the model (the best: {rows[best]['iae']:.2f}x its IAE)"
    given = {**({"law": law} if law else {}), **CANDIDATES[best]}
    options = MPCOptions.resolve(given, model.problem)
    model = condition(model)   # measured disturbances held: the controller's design
    cert = compute_certificate(model, gain_scale=0.0, **design_arguments(options, model))
    if cert.rho_s > RHO_HINT:
        cap = faster_contraction(cert.rho_s)
        text += (f": the certified terminal weight s = {cert.s:,.0f} (rho_s = "
                 f"{cert.rho_s:.4f}) makes ending a horizon away from the steady state costly, "
                 "so every weighting approaches it slowly; a model trained to contract faster "
                 f"has at most a tenth of it: cosim train --rho-max {cap:.3f} (or [train] "
                 f"rho_max = {cap:.3f} in the problem file), then compare on the plant: "
                 "cosim campaign")
    return text


def faster_contraction(rho_s: float) -> float:
    """The contraction cap whose terminal weight is at most a tenth of ``rho_s``'s
    (``s ∝ 1/(1 − ρ_s²)``, ``eq:definition_s``): ``√(1 − 10 (1 − ρ_s²))``, inside
    [0.8, 0.99]."""
    return float(min(0.99, max(0.8, (max(0.0, 1.0 - 10.0 * (1.0 - rho_s ** 2))) ** 0.5)))


def _save(path: Path, model: Any, options: dict[str, Any]) -> None:
    """The model file with ``options`` over its problem's ``[mpc]`` table (atomic: a failed
    write leaves it as it was)."""
    import dataclasses

    from cosim.core.atomicio import output_error

    model.problem = dataclasses.replace(model.problem, mpc={**model.problem.mpc, **options})
    try:
        model.save(path)
    except OSError as exc:
        raise output_error(path, exc) from None
