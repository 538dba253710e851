"""Independent Python reference of the four-tank plant, for the FMU's proofs.

The same ODE as ``fmus/fourtank/model.c`` (Schimperna & Magni, section V, plus the extra
inflows ``qd``), written again in Python and solved with scipy's ``solve_ivp`` at tight
tolerances. Run this file to regenerate ``fmus/fourtank/reference/step.csv``::

    .venv/bin/python tests/fmus/fourtank_reference.py
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

#: Alvarado et al. 2011 parameters (SI units), as in the model descriptions.
PARAMETERS = {
    "S": 0.06,
    "a1": 1.31e-4,
    "a2": 1.51e-4,
    "a3": 9.27e-5,
    "a4": 8.82e-5,
    "gamma_a": 0.3,
    "gamma_b": 0.4,
}
G = 9.81
#: Default start levels of the FMU (an equilibrium with h1 = h2 = 0.65 m).
H_START = (0.65, 0.65, 0.6514031296511584, 0.6638294000727866)
#: Default pump flows of the FMU (the inputs of that equilibrium) [m3/s].
Q_EQ = (4.5472443083696316e-4, 5.5233543431505480e-4)
#: Pump limits of the paper (section V) [m3/s].
QA_MAX = 9.05e-4
QB_MAX = 11.1e-4
TS = 25.0

REFERENCE_CSV = Path(__file__).resolve().parents[2] / "fmus" / "fourtank" / "reference" / "step.csv"


def rhs(h, qa: float, qb: float, qd=(0.0, 0.0, 0.0, 0.0), p=PARAMETERS) -> list[float]:
    """Four-tank right-hand side (section V) with the empty-tank rules of ``model.c``.

    Outflow uses max(h, 0); a tank at h <= 0 cannot fall further (negative rate cut to 0).
    """
    out = [p[f"a{i + 1}"] * math.sqrt(2.0 * G * max(h[i], 0.0)) for i in range(4)]
    inflow = (
        out[2] + p["gamma_a"] * qa + qd[0],
        out[3] + p["gamma_b"] * qb + qd[1],
        (1.0 - p["gamma_b"]) * qb + qd[2],
        (1.0 - p["gamma_a"]) * qa + qd[3],
    )
    dh = [(inflow[i] - out[i]) / p["S"] for i in range(4)]
    return [0.0 if (h[i] <= 0.0 and dh[i] < 0.0) else dh[i] for i in range(4)]


def random_inputs(n_steps: int, seed: int, max_hold: int = 40, p_off: float = 0.15) -> np.ndarray:
    """Multilevel pseudo-random pump flows, shape (n_steps, 2), held for random times.

    Each hold lasts 1..max_hold samples; with probability ``p_off`` both pumps are off (tanks
    drain, some to empty), otherwise each level is uniform in the paper's limits.
    """
    rng = np.random.default_rng(seed)
    u = np.empty((n_steps, 2))
    k = 0
    while k < n_steps:
        hold = int(rng.integers(1, max_hold + 1))
        if rng.random() < p_off:
            level = (0.0, 0.0)
        else:
            level = (rng.uniform(0.0, QA_MAX), rng.uniform(0.0, QB_MAX))
        u[k : k + hold] = level
        k += hold
    return u


def simulate_reference(
    u: np.ndarray,
    h0=H_START,
    ts: float = TS,
    rtol: float = 1e-10,
    atol: float = 1e-14,
    params: dict[str, float] = PARAMETERS,
) -> np.ndarray:
    """Levels at every sample, shape (len(u) + 1, 4), for inputs held over each sample.

    Integrates each run of equal inputs with ``solve_ivp`` (DOP853) and restarts the solver
    at every input change, where the right-hand side is discontinuous.
    """
    n = len(u)
    y = np.empty((n + 1, 4))
    y[0] = h0
    k = 0
    while k < n:
        j = k + 1
        while j < n and np.array_equal(u[j], u[k]):
            j += 1
        qa, qb = float(u[k, 0]), float(u[k, 1])
        t_eval = ts * np.arange(1, j - k + 1)
        sol = solve_ivp(
            lambda _t, h, qa=qa, qb=qb: rhs(h, qa, qb, p=params),
            (0.0, t_eval[-1]),
            y[k],
            method="DOP853",
            t_eval=t_eval,
            rtol=rtol,
            atol=atol,
        )
        if not sol.success:
            raise RuntimeError(f"reference solve failed at sample {k}: {sol.message}")
        y[k + 1 : j + 1] = np.maximum(sol.y.T, 0.0)
        k = j
    return y


def step_scenario() -> tuple[np.ndarray, np.ndarray]:
    """The shipped reference: 200 samples from the default equilibrium, with pump steps.

    Returns inputs (200, 2) and levels (201, 4).
    """
    u = np.empty((200, 2))
    u[:] = Q_EQ
    u[20:80] = (6.0e-4, Q_EQ[1])  # pump A up
    u[80:120] = (6.0e-4, 8.0e-4)  # pump B up
    u[120:160] = (0.0, 0.0)  # both off: the upper tanks drain to empty
    u[160:] = (QA_MAX, 2.0e-4)  # refill
    return u, simulate_reference(u)


def write_step_csv(path: Path = REFERENCE_CSV) -> None:
    """Write ``step.csv``: time, the inputs held from that time, and the levels."""
    u, y = step_scenario()
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "qa", "qb", "h1", "h2", "h3", "h4"])
        for k in range(len(y)):
            uk = u[min(k, len(u) - 1)]
            w.writerow([f"{k * TS:g}", *(f"{v:.17g}" for v in uk), *(f"{v:.17g}" for v in y[k])])


def read_step_csv(path: Path = REFERENCE_CSV) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read ``step.csv``: times (201,), inputs (200, 2), levels (201, 4)."""
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return data[:, 0], data[:-1, 1:3], data[:, 3:7]


if __name__ == "__main__":
    write_step_csv()
    print(f"wrote {REFERENCE_CSV}")
