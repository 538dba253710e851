"""Tuning the robust MPC on its model: the cost weights chosen as the PI baseline is tuned.

:func:`tune` runs the robust MPC (its default law, :data:`controllers.laws.DEFAULT`, or the law
asked for) with the weightings of :data:`CANDIDATES`,
and the PI baseline tuned from the same model, in closed loop with the GRU model itself as the
plant (``plant = "model:…"``: no FMU needed) on a set-point scenario (given, else
:func:`scenario`: steps between four steady outputs of the model, each held six of its slowest
time constants, with Gaussian sensor noise whose standard deviation is the model's measured
one-step prediction error: an upper estimate of the sensors' noise, so that a weighting that
passes noise on to the inputs loses where the data were noisy), and keeps the weighting with
the lowest summed IAE (each output's IAE over its box width) among those without constraint
violations whose input total variation is at most ``tv_ratio`` times the PI's
(:func:`choose`); a plant that is not square has no PI baseline, and the default weights are
the reference. ``save=True`` writes the choice into the model file's problem as its ``[mpc]``
table (:attr:`controllers.problem.ControlProblem.mpc`), which every later run of the model
uses under its own options. ``cosim tune`` is its command (:mod:`cosim.commands.tune`).
"""

from __future__ import annotations

import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CANDIDATES", "RHO_HINT", "TuneResult", "choose", "faster_contraction", "hint",
           "scenario", "tune"]

#: The weightings tried (robust-MPC options; ``Q``, ``R``, ``du_weight`` in normalised units).
CANDIDATES: dict[str, dict[str, Any]] = {
    "defaults": {"Q": 1.0, "R": 0.01, "du_weight": 0.05},
    "output cost": {"Q": "outputs", "R": 0.01, "du_weight": 0.05},
    "output cost, light inputs": {"Q": "outputs", "R": 0.001, "du_weight": 0.01},
    "output cost, free inputs": {"Q": "outputs", "R": 0.001, "du_weight": 0.0},
}
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
        Candidate name → ``iae`` and ``tv`` (summed, over the reference's) and ``violations``.
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
         workers: int = 0, law: str | None = None) -> TuneResult:
    """Tune the robust MPC's weights on ``model`` (module docstring) for its law ``law``
    (default: :data:`controllers.laws.DEFAULT`). The closed loops run
    in ``workers`` processes (0: one per CPU, at most one per run, unless the runs are short:
    :data:`WORKER_STEPS`; 1: in this process): the same answer either way. Interrupted
    (Ctrl-C), the workers are stopped and the model file is left as it was.

    Raises
    ------
    ParameterError
        A bad ``tv_ratio``.
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
        results = _closed_loops(model, sc, square, progress, workers, gru.problem.Ts,
                                law or laws.DEFAULT)
    base = results.pop("pi") if square else results["defaults"]
    rows = {n: {"iae": r["iae"] / base["iae"],
                "tv": r["tv"] / base["tv"] if base["tv"] else 0.0,
                "violations": r["violations"]} for n, r in results.items()}
    best = choose(rows, tv_ratio)
    result = TuneResult(rows, best, "pi" if square else "defaults",
                        hint(gru, rows, best, law or laws.DEFAULT) if square else None,
                        Path(scenario_file) if scenario_file else None, law=law)
    if save:
        _save(Path(model), gru, result.options)
        result.saved = True
    return result


def _closed_loops(model: str | Path, sc: Path, square: bool, progress: bool, workers: int,
                  ts: float, law: str) -> dict[str, dict[str, float]]:
    """:func:`_score` of the PI (square plants) and of every candidate, the model as the
    plant: in ``workers`` spawned processes (0: one per CPU, at most one per run, when the
    runs have more than :data:`WORKER_STEPS` steps together, else 1; 1: in this process), one
    progress bar over all their steps."""
    import os

    from tqdm import tqdm

    from cosim.core import scenario as scenario_mod
    from cosim.core.master import communication_times

    runs: dict[str, Any] = {"pi": None, **CANDIDATES} if square else dict(CANDIDATES)
    loaded = scenario_mod.load(sc)
    steps = len(communication_times(loaded.start_time, loaded.stop_time, ts)) - 1
    jobs = [(name, str(model), str(sc), None if options is None else {"law": law, **options})
            for name, options in runs.items()]
    if not workers:   # a worker takes about a second to start: not worth it for short runs
        workers = (min(len(jobs), os.cpu_count() or 1) if steps * len(jobs) > WORKER_STEPS
                   else 1)
    bar = tqdm(total=steps * len(jobs), desc="tune", unit="step", file=sys.stderr,
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
    return {name: score for (name, *_), score in zip(jobs, scores, strict=True)}


def _closed_loop(job: tuple[str, str, str, Any], tick: Any = None) -> dict[str, float]:
    """One tuning run (the PI when ``options`` is ``None``), scored; a run that ended
    degraded (its controller did not serve a tenth of the steps) scores an infinite IAE and
    input motion, so that it is never chosen."""
    import cosim
    from cosim.core.errors import SimulationFailed

    name, model, sc, options = job
    controller = "pi" if options is None else "robust-mpc"
    opts = dict(options) if options is not None else {}
    out = cosim.run(sc, plant=f"model:{model}", controller=controller, model=model,
                    options=opts, seed=0, on_step=tick)
    if out.status == "degraded":   # not a candidate: its controller did not serve
        return {"iae": math.inf, "tv": math.inf, "violations": 0}
    if out.status != "ok":
        raise SimulationFailed(f"{name}: the run {out.status}: {out.reason}")
    return _score(out.summary)


def scenario(model: Any, path: Path) -> Path:
    """Write the generated scenario (module docstring) of ``model`` to ``path``."""
    from controllers.equilibrium import equilibrium_output, jacobians

    problem, params = model.problem, model.params
    lo, hi = np.array(problem.output_bounds).T
    targets, slowest = [], 0.0
    for k in range(len(PATTERN)):
        u = np.array([c.min + PATTERN[(k + j) % len(PATTERN)] * (c.max - c.min)
                      for j, c in enumerate(problem.inputs)]
                     + [0.5 * (c.min + c.max) for c in problem.disturbances])
        un = model.normalize_u(u)   # the model's inputs: the measured disturbances mid-box
        x, y = equilibrium_output(params, un)
        rho = float(np.max(np.abs(np.linalg.eigvals(jacobians(params, x, un)[0]))))
        slowest = max(slowest, -1.0 / math.log(min(max(rho, 1e-12), 1.0 - 1e-12)))
        targets.append(np.clip(model.denormalize_y(y), lo + 0.05 * (hi - lo),
                               hi - 0.05 * (hi - lo)))
    hold = int(min(max(math.ceil(HOLD_TIME_CONSTANTS * slowest), HOLD_MIN), HOLD_MAX))
    noise = _noise(model)
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


def _noise(model: Any) -> np.ndarray:
    """Sensor noise std per output [its unit]: the measured one-step prediction error (its
    95th percentile, :mod:`controllers.certification.prediction_error`), else ``w̄_y``, else
    none; an upper estimate on purpose (module docstring)."""
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


def choose(rows: dict[str, dict[str, float]], tv_ratio: float) -> str:
    """The candidate of ``rows`` (name → :func:`_score` ratios to the PI: ``iae``, ``tv``,
    ``violations``) with the lowest IAE within the TV bound and without violations, else
    ``"defaults"``."""
    ok = [n for n, r in rows.items() if r["violations"] == 0 and r["tv"] <= tv_ratio]
    return min(ok, key=lambda n: rows[n]["iae"]) if ok else "defaults"


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
