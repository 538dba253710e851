"""Identification data: a multilevel pseudo-random excitation of a plant, sampled every Ts.

The paper's section V (``sec:numerical-example``): ``qa`` and ``qb`` are piecewise constant
with random levels inside the saturation box and random hold times; the plant response is
sampled every ``Ts = 25 s``; 20,000 steps are split 15,000 / 2,500 / 2,500 into training,
validation and test data.

Row ``k`` of the data set holds ``u_k`` (applied over ``[t_k, t_k + Ts)``) and ``y_k``
(measured at ``t_k``, before ``u_k`` acts), which is the timing of ``eq:gru``:
``ξ_k = g(x_k)``, ``x_{k+1} = f(x_k, u_k)``.

CSV format: a header ``time,<inputs...>,<outputs...>,split`` then one row per sample, with
``split`` one of ``train``, ``val``, ``test``. A sidecar ``<name>.json`` records how the data
were made (seed, plant, hold times, splits) so that they can be regenerated exactly. Both
files are written atomically (:mod:`cosim.core.atomicio`): a failed write leaves the previous pair
unchanged.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core import csvio
from cosim.core.component import Component
from cosim.core.errors import CosimError

__all__ = ["DATA_WORDING", "SPLITS", "Dataset", "collect", "fmu_plant",
           "generate", "multilevel_signal", "read_csv", "split_sizes", "write_csv"]

#: Names of the three parts of a data set, in time order.
SPLITS = ("train", "val", "test")


@dataclass
class Dataset:
    """An input/output record with its split.

    Attributes
    ----------
    time : (T,) array
    u : (T, m) array
        Inputs, physical units.
    y : (T, q) array
        Measured outputs, physical units (all plant outputs recorded, e.g. h1..h4).
    input_names, output_names : list of str
    split : (T,) array of str
        ``train`` / ``val`` / ``test`` per row.
    """

    time: np.ndarray
    u: np.ndarray
    y: np.ndarray
    input_names: list[str]
    output_names: list[str]
    split: np.ndarray

    def part(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Inputs and outputs of one split (``train``, ``val`` or ``test``)."""
        mask = self.split == name
        return self.u[mask], self.y[mask]

    def outputs(self, names: Sequence[str]) -> np.ndarray:
        """Columns of :attr:`y` by name."""
        try:
            idx = [self.output_names.index(n) for n in names]
        except ValueError as exc:
            raise CosimError(f"data set has no output {exc.args[0].split()[0]}; it has "
                             f"{', '.join(self.output_names)}") from None
        return self.y[:, idx]


def split_sizes(steps: int, fractions: tuple[float, float] = (0.75, 0.125)) -> tuple[int, ...]:
    """Train/validation/test sizes; 20,000 steps give the paper's 15,000/2,500/2,500."""
    n_train = round(steps * fractions[0])
    n_val = round(steps * fractions[1])
    return n_train, n_val, steps - n_train - n_val


def multilevel_signal(steps: int, bounds: Sequence[tuple[float, float]],
                      rng: np.random.Generator,
                      hold: tuple[int, int] | Sequence[tuple[int, int]] = (2, 80)
                      ) -> np.ndarray:
    """Multilevel pseudo-random signal: piecewise constant, random levels and hold times.

    Each input channel is independent. Levels are uniform inside its ``(min, max)`` box; hold
    times (in samples) are log-uniform on ``[hold[0], hold[1]]`` (one pair for every channel,
    or one per channel), so that short holds excite the fast dynamics and long ones let the
    plant settle (the four-tank time constants are about 7-17 samples of 25 s).

    Returns
    -------
    (steps, m) array
    """
    holds = [tuple(hold)] * len(bounds) if np.ndim(hold) == 1 else [tuple(h) for h in hold]
    if len(holds) != len(bounds):
        raise CosimError(f"{len(holds)} hold-time pairs for {len(bounds)} inputs")
    for pair in holds:
        if not 1 <= pair[0] <= pair[1]:
            raise CosimError(f"hold times must satisfy 1 <= min <= max, got {pair}")
    u = np.empty((steps, len(bounds)))
    for j, (lo, hi) in enumerate(bounds):
        lo_hold, hi_hold = holds[j]
        k = 0
        while k < steps:
            length = int(np.exp(rng.uniform(np.log(lo_hold), np.log(hi_hold + 1))))
            length = max(lo_hold, min(hi_hold, length))
            u[k:k + length, j] = rng.uniform(lo, hi)
            k += length
    return u


def collect(plant: Component, u: np.ndarray, Ts: float, input_names: Sequence[str],
            output_names: Sequence[str], progress: bool = True) -> np.ndarray:
    """Drive ``plant`` with ``u`` (one row per sample) and sample its outputs.

    Returns ``y`` with ``y[k]`` measured at ``t_k = k Ts`` before ``u[k]`` acts.
    """
    from tqdm import tqdm

    steps = u.shape[0]
    y = np.empty((steps, len(output_names)))
    plant.setup(0.0)
    try:
        for k in tqdm(range(steps), desc="generate-data", unit="step", disable=not progress):
            out = plant.get_outputs()
            try:
                y[k] = [out[name] for name in output_names]
            except KeyError as exc:
                raise CosimError(f"plant has no output {exc.args[0]!r}") from None
            plant.set_inputs(dict(zip(input_names, u[k].tolist(), strict=True)))
            plant.step(k * Ts, Ts)
    finally:
        plant.terminate()
    if not np.all(np.isfinite(y)):
        raise CosimError("plant produced non-finite outputs")
    return y


def generate(plant: Component, steps: int, seed: int, bounds: Sequence[tuple[float, float]],
             input_names: Sequence[str], output_names: Sequence[str], Ts: float,
             hold: tuple[int, int] | Sequence[tuple[int, int]] = (2, 80),
             progress: bool = True) -> Dataset:
    """Excite ``plant`` with :func:`multilevel_signal` and return the split data set."""
    rng = np.random.default_rng(seed)
    u = multilevel_signal(steps, bounds, rng, hold)
    y = collect(plant, u, Ts, input_names, output_names, progress)
    sizes = split_sizes(steps)
    split = np.repeat(np.array(SPLITS), sizes)
    return Dataset(time=np.arange(steps) * Ts, u=u, y=y, input_names=list(input_names),
                   output_names=list(output_names), split=split)


def write_csv(data: Dataset, path: str | Path, meta: dict | None = None) -> Path:
    """Write the CSV and its ``.json`` sidecar (``meta`` plus split sizes); return the CSV.

    Both files are written to temporary files first and renamed onto their targets only when
    both are complete (:func:`cosim.core.atomicio.replacing`), so a failed write leaves the
    previous CSV and sidecar unchanged.

    Raises
    ------
    OutputError
        Naming the file that could not be written (full disk, unwritable folder).
    CosimError
        When ``path`` ends in ``.json`` (the sidecar would overwrite the data).
    """
    from cosim.core.atomicio import output_error, replacing

    path = Path(path)
    side = path.with_suffix(".json")
    if side == path:
        raise CosimError(f"{path}: a data file cannot end in .json: that name is its sidecar")
    sidecar = dict(meta or {})
    sidecar.update({"inputs": data.input_names, "outputs": data.output_names,
                    "steps": int(data.time.shape[0]),
                    "splits": {s: int(np.sum(data.split == s)) for s in SPLITS}})
    with replacing(path) as tmp_csv, replacing(side) as tmp_json:
        try:
            with open(tmp_csv, "w", newline="", encoding="utf-8") as fh:
                csvio.write_table(fh, ["time", *data.input_names, *data.output_names, "split"],
                                  ([float(data.time[k]), *data.u[k].tolist(),
                                    *data.y[k].tolist(), data.split[k]]
                                   for k in range(data.time.shape[0])))
        except OSError as exc:
            raise output_error(path, exc) from None
        try:
            tmp_json.write_text(json.dumps(sidecar, indent=1) + "\n", encoding="utf-8")
        except OSError as exc:
            raise output_error(side, exc) from None
    return path


#: How data sets word the errors of :class:`~cosim.core.csvio.CsvReader`.
DATA_WORDING = csvio.Wording(
    not_found="{path}: cannot read data file ({strerror})",
    is_folder="{path}: cannot read data file ({strerror})",
    unreadable="{path}: cannot read data file ({strerror})",
    not_text="{path}:{line}: not a text CSV file (byte {start} of a read block is not UTF-8)",
    malformed="{path}:{line}: malformed CSV ({error})",
    empty="{path}:1: header must be 'time,<signals...>,split'",
    cell_count="{path}:{line}: expected {expected} fields, got {cells}",
    empty_value=None,
    not_a_number="{path}:{line}: non-numeric value",
    not_finite="{path}:{line}: non-finite value",
)


def read_csv(path: str | Path, n_inputs: int | None = None,
             input_names: Sequence[str] | None = None) -> Dataset:
    """Read a data set written by :func:`write_csv`.

    The inputs are the columns named ``input_names`` (default: the sidecar's ``inputs``, else
    the first ``n_inputs`` after ``time``, else ``qa, qb``); every other numeric column except
    ``time`` and ``split`` is an output. Errors name the file and line.
    """
    path = Path(path)
    with csvio.CsvReader(path, DATA_WORDING) as f:
        header = f.header()
        if not header or header[0] != "time" or header[-1] != "split":
            raise f.error(DATA_WORDING.empty)
        signals = header[1:-1]
        rows, split = [], []
        for line, row in f.rows(len(header), skip_blank=False):
            values = [f.number(v, line, j, name, finite=False)
                      for j, (v, name) in enumerate(zip(row[:-1], header, strict=False), start=1)]
            if not all(np.isfinite(values)):
                raise f.error(DATA_WORDING.not_finite, line=line)
            if row[-1] not in SPLITS:
                raise CosimError(f"{path}:{line}: split must be one of {', '.join(SPLITS)}, "
                                 f"got {row[-1]!r}")
            rows.append(values)
            split.append(row[-1])
    if not rows:
        raise CosimError(f"{path}: no data rows")
    input_names = _input_names(path, signals, n_inputs, input_names)
    missing = [n for n in input_names if n not in signals]
    if missing:
        raise CosimError(f"{path}:1: no input column {missing[0]!r}")
    arr = np.array(rows)
    in_idx = [1 + signals.index(n) for n in input_names]
    out_names = [n for n in signals if n not in input_names]
    out_idx = [1 + signals.index(n) for n in out_names]
    return Dataset(time=arr[:, 0], u=arr[:, in_idx], y=arr[:, out_idx],
                   input_names=list(input_names), output_names=out_names,
                   split=np.array(split))


def _input_names(path: Path, signals: list[str], n_inputs: int | None,
                 input_names: Sequence[str] | None) -> Sequence[str]:
    """The input columns: as given, else the sidecar's, else the first ``n_inputs``."""
    if input_names is not None:
        return input_names
    sidecar = path.with_suffix(".json")
    if sidecar.exists():
        try:
            input_names = json.loads(sidecar.read_text(encoding="utf-8"))["inputs"]
        except (OSError, ValueError, KeyError, TypeError, RecursionError):
            input_names = None  # an unreadable sidecar is ignored, as if missing
        if not (isinstance(input_names, list) and all(isinstance(n, str) for n in input_names)):
            input_names = None
    if input_names is None:
        input_names = signals[:n_inputs] if n_inputs else ["qa", "qb"]
    return input_names


def fmu_plant(path: str | Path, map_path: str | Path | None = None,
              interface: str = "cs", varmap: Any = None) -> Component:
    """The plant FMU as a :class:`~cosim.core.fmu.FmuComponent`, with a variable map: ``varmap``
    (a :class:`~cosim.core.varmap.VarMap`, e.g. a problem's binding, :mod:`cosim.core.binding`), or
    the one read from ``map_path``."""
    from cosim.core import varmap as varmaps
    from cosim.core.fmu import FmuComponent

    vm = varmap if varmap is not None else (varmaps.load(map_path) if map_path else None)
    return FmuComponent(path, name="plant", interface=interface, varmap=vm)
