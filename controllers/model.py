"""The GRU model file (``controllers/models/*.json``): weights, normalisation, metadata.

Format (JSON, no pickle anywhere)::

    {
      "format": "gru-mpc-model", "version": 1,
      "Ts": 25.0,
      "inputs":  [{"name": "qa", "unit": "m3/s"}, ...],          # m entries
      "outputs": [{"name": "h1", "unit": "m"}, ...],             # p entries
      "W_z": [[...]], "U_z": [[...]], "b_z": [...],               # n×m, n×n, n
      "W_r": ..., "U_r": ..., "b_r": ..., "W_h": ..., "U_h": ..., "b_h": ...,
      "U_o": [[...]], "b_o": [...],                               # p×n, p
      "normalization": {"u_offset": [...], "u_scale": [...],
                        "y_offset": [...], "y_scale": [...]},    # normalised = (raw − offset)/scale
      "training": {...},                                          # free-form record
      "observer": {"L_z": [[...]], "L_r": [[...]]},               # optional, n×p each
      "w_y_bar": 0.12,                                            # optional, normalised units
      "prediction_error": [[...]],                                # optional, (H+1)×p, normalised
      "certificate": {...},                                       # optional, cosim certify --save
      "problem": {...}                                            # the control problem
    }

``problem`` is the control problem the model was trained for
(:class:`controllers.problem.ControlProblem`, copied from the data set by ``cosim train``):
its inputs and outputs must be the model's, in the same order, with the same units, sample
time and normalisation. Model files written before problems existed have none; every stage
that needs one then asks for it (``--problem``).

Matrices are nested lists, row-major. Inputs are normalised so that the saturation box maps
to ``‖u‖∞ ≤ 1`` (``eq:input-constraint``).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controllers.errors import ControllersError, ModelFileError
from controllers.gru import PARAM_NAMES, WEIGHT_LIMIT

__all__ = ["DEFAULT_MODEL", "FORMAT_NAME", "FORMAT_VERSION", "NORMALIZATION_KEYS", "GRUModel",
           "write_atomic"]

#: The shipped model: the four-tank GRU of ``controllers/models/`` (trained by ``cosim
#: train``, observer gains by ``cosim certify --auto-gain-scale --save``).
DEFAULT_MODEL = Path(__file__).resolve().parent / "models" / "fourtank_gru.json"

FORMAT_NAME = "gru-mpc-model"
FORMAT_VERSION = 1
NORMALIZATION_KEYS = ("u_offset", "u_scale", "y_offset", "y_scale")


@dataclass
class GRUModel:
    """A GRU model in the paper's convention with its physical-unit normalisation.

    Attributes
    ----------
    params : dict of ndarray
        ``W_z U_z b_z W_r U_r b_r W_h U_h b_h U_o b_o`` (``eq:gru``).
    u_offset, u_scale, y_offset, y_scale : ndarray
        ``normalised = (raw − offset) / scale``.
    input_names, input_units, output_names, output_units : list of str
        The model's inputs are the problem's manipulated inputs then its measured
        disturbances (:attr:`controllers.problem.ControlProblem.model_inputs`).
    Ts : float
        Sample time [s].
    training : dict
        Free-form training record (seed, epochs, FIT, ν, …).
    L_z, L_r : ndarray or None
        Observer gains of ``eq:observer`` (n×p), when designed.
    w_y_bar : float or None
        Bound of the output perturbation, normalised units (``W_y``).
    prediction_error : ndarray or None
        ``(H + 1, p)``: the measured error of the tracking law's prediction ``i`` steps ahead
        on held-back data, normalised (:mod:`controllers.certification.prediction_error`; written by
        ``cosim train``): the tightening of the robust MPC's uncertified mode.
    certificate : dict or None
        What ``cosim certify --save`` found (``certified``, the law, the reasons, …).
    problem : ControlProblem or None
        The control problem (signals, boxes, sample time, normalisation, PI loops).
    source : str or None
        The file the model was loaded from (:meth:`load`), for error messages; not saved.
    held_from : GRUModel or None
        The full model a conditioned one holds the disturbances of
        (:func:`controllers.disturbances.condition`); its certificate bounds come from it.
    """

    params: dict[str, np.ndarray]
    u_offset: np.ndarray
    u_scale: np.ndarray
    y_offset: np.ndarray
    y_scale: np.ndarray
    input_names: list[str]
    input_units: list[str]
    output_names: list[str]
    output_units: list[str]
    Ts: float
    training: dict[str, Any] = field(default_factory=dict)
    L_z: np.ndarray | None = None
    L_r: np.ndarray | None = None
    w_y_bar: float | None = None
    prediction_error: np.ndarray | None = None
    certificate: dict[str, Any] | None = None
    problem: Any = None
    source: str | None = field(default=None, compare=False, repr=False)
    #: the full model (inputs and measured disturbances) this one is conditioned on, with the
    #: disturbances held in its biases (:func:`controllers.disturbances.condition`); not saved
    held_from: Any = field(default=None, compare=False, repr=False)

    @property
    def n(self) -> int:
        """Number of states."""
        return self.params["U_z"].shape[0]

    @property
    def m(self) -> int:
        """Number of model inputs (manipulated inputs and measured disturbances)."""
        return self.params["W_z"].shape[1]

    @property
    def q(self) -> int:
        """Number of measured disturbances among the inputs (the last ``q``)."""
        return self.problem.q if self.problem is not None else 0

    @property
    def m_u(self) -> int:
        """Number of manipulated inputs (the first ``m_u`` model inputs)."""
        return self.m - self.q

    @property
    def p(self) -> int:
        """Number of outputs."""
        return self.params["U_o"].shape[0]

    # -- unit conversion ---------------------------------------------------------------
    def normalize_u(self, u: np.ndarray) -> np.ndarray:
        """Physical inputs → normalised inputs."""
        return (np.asarray(u, dtype=float) - self.u_offset) / self.u_scale

    def denormalize_u(self, u: np.ndarray) -> np.ndarray:
        """Normalised inputs → physical inputs."""
        return np.asarray(u, dtype=float) * self.u_scale + self.u_offset

    def normalize_y(self, y: np.ndarray) -> np.ndarray:
        """Physical outputs → normalised outputs."""
        return (np.asarray(y, dtype=float) - self.y_offset) / self.y_scale

    def denormalize_y(self, y: np.ndarray) -> np.ndarray:
        """Normalised outputs → physical outputs."""
        return np.asarray(y, dtype=float) * self.y_scale + self.y_offset

    # -- (de)serialisation -------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The JSON document of this model (see the module docstring)."""
        doc: dict[str, Any] = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "Ts": float(self.Ts),
            "inputs": [{"name": n, "unit": u}
                       for n, u in zip(self.input_names, self.input_units, strict=True)],
            "outputs": [{"name": n, "unit": u}
                        for n, u in zip(self.output_names, self.output_units, strict=True)],
        }
        for name in PARAM_NAMES:
            doc[name] = np.asarray(self.params[name], dtype=float).tolist()
        doc["normalization"] = {k: np.asarray(getattr(self, k), dtype=float).tolist()
                                for k in NORMALIZATION_KEYS}
        doc["training"] = self.training
        if self.L_z is not None and self.L_r is not None:
            doc["observer"] = {"L_z": self.L_z.tolist(), "L_r": self.L_r.tolist()}
        if self.w_y_bar is not None:
            doc["w_y_bar"] = float(self.w_y_bar)
        if self.prediction_error is not None:
            doc["prediction_error"] = np.asarray(self.prediction_error, dtype=float).tolist()
        if self.certificate is not None:
            doc["certificate"] = self.certificate
        if self.problem is not None:
            doc["problem"] = self.problem.to_dict()
        return doc

    def to_json(self) -> str:
        """The text of the model file (JSON, full float precision, newline-terminated)."""
        return json.dumps(self.to_dict(), indent=1) + "\n"

    def save(self, path: str | Path) -> None:
        """Write the model file atomically (JSON, full float precision).

        Nothing is written that would not load: the text is read back as :meth:`load`
        reads it first. It goes to a temporary file beside ``path`` that is flushed to disk
        and renamed onto ``path`` (:func:`write_atomic`): a failed write (full disk,
        unwritable folder) leaves the previous file byte-identical.

        Raises
        ------
        ModelFileError
            The model would not load (a non-finite or absurd weight); ``path`` is unchanged.
        OSError
            When the file cannot be written; ``path`` is then unchanged.
        """
        try:
            text = self.to_json()
            type(self).from_dict(json.loads(text), source="the model")
        except ValueError as exc:   # what load would refuse (a ModelFileError)
            raise ModelFileError(f"{path}: not written, it would not load: {exc}") from None
        write_atomic(path, text)

    @classmethod
    def load(cls, path: str | Path) -> GRUModel:
        """Read and validate a model file; raise :class:`ModelFileError` on any fault."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ModelFileError(f"{path}: cannot read model file ({exc.strerror})") from None
        except UnicodeDecodeError as exc:
            raise ModelFileError(f"{path}: not a JSON model file (byte {exc.start} is not "
                                 "UTF-8)") from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ModelFileError(
                f"{path}:{exc.lineno}:{exc.colno}: invalid JSON ({exc.msg})") from None
        except RecursionError:
            raise ModelFileError(f"{path}: invalid model file (JSON nested too deeply)") from None
        except ValueError as exc:  # e.g. an integer literal with more than 4300 digits
            raise ModelFileError(f"{path}: invalid JSON ({exc})") from None
        model = cls.from_dict(doc, source=str(path))
        model.source = str(path)
        return model

    @classmethod
    def from_dict(cls, doc: Any, source: str = "<model>") -> GRUModel:
        """Build a model from its JSON document, validating names, shapes and values."""
        if not isinstance(doc, dict):
            raise ModelFileError(f"{source}: top level must be a JSON object")
        if doc.get("format", FORMAT_NAME) != FORMAT_NAME:
            raise ModelFileError(f"{source}: 'format' is {doc.get('format')!r}, "
                                 f"expected {FORMAT_NAME!r}")
        version = doc.get("version", FORMAT_VERSION)
        if version != FORMAT_VERSION or isinstance(version, bool):
            raise ModelFileError(f"{source}: 'version' is {version!r}, this cosim reads "
                                 f"version {FORMAT_VERSION}")

        params = _params(doc, source)
        n, m = params["W_z"].shape
        p = params["U_o"].shape[0]
        scales = _normalization(doc, source, m, p)
        input_names, input_units = _signals(doc, "inputs", m, source)
        output_names, output_units = _signals(doc, "outputs", p, source)
        Ts = doc.get("Ts")
        if (not isinstance(Ts, int | float) or isinstance(Ts, bool) or not math.isfinite(Ts)
                or Ts <= 0):
            raise ModelFileError(f"{source}: 'Ts' must be a positive number, got {Ts!r}")
        L_z, L_r, w_y_bar, training, profile, certificate = _design_entries(doc, source, n, p)

        model = cls(params=params, u_offset=scales["u_offset"], u_scale=scales["u_scale"],
                    y_offset=scales["y_offset"], y_scale=scales["y_scale"],
                    input_names=input_names, input_units=input_units,
                    output_names=output_names, output_units=output_units, Ts=float(Ts),
                    training=training, L_z=L_z, L_r=L_r,
                    w_y_bar=None if w_y_bar is None else float(w_y_bar),
                    prediction_error=profile, certificate=certificate)
        if doc.get("problem") is not None:
            from controllers.problem_file import problem_from_dict

            try:
                problem = problem_from_dict(doc["problem"], source)
            except ControllersError as exc:
                raise ModelFileError(str(exc)) from None
            model.problem = problem
            bad = model.mismatch(problem)
            if bad:
                raise ModelFileError(f"{source}: its problem {problem.name!r} does not match "
                                     f"the model: {bad}")
        return model

    def mismatch(self, problem: Any) -> str:
        """How ``problem`` contradicts this model's signals, sample time or normalisation
        (an empty string when it does not)."""
        names = list(problem.model_input_names)
        units = [c.unit for c in problem.model_inputs]
        if names != list(self.input_names) or list(
                problem.output_names) != list(self.output_names):
            return (f"signals {names} -> {list(problem.output_names)} vs "
                    f"the model's {self.input_names} -> {self.output_names}")
        if units != list(self.input_units) or list(
                problem.output_units) != list(self.output_units):
            return (f"units {units} -> {list(problem.output_units)} vs the "
                    f"model's {self.input_units} -> {self.output_units}")
        if not math.isclose(problem.Ts, self.Ts, rel_tol=1e-12):
            return f"Ts {problem.Ts:g} s vs the model's {self.Ts:g} s"
        norm = problem.normalization()
        for key in NORMALIZATION_KEYS:
            if not np.allclose(norm[key], getattr(self, key), rtol=1e-12, atol=0.0):
                return (f"normalization {key} {norm[key].tolist()} vs the model's "
                        f"{np.asarray(getattr(self, key)).tolist()}")
        return ""


def _file_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def write_atomic(path: str | Path, text: str) -> None:
    """Replace ``path`` with ``text`` (UTF-8) in one step: temporary file, fsync, rename.

    The temporary file ``.<name>.<random>.tmp<suffix>`` is created in the target's folder
    (created when missing), flushed to disk and renamed onto ``path`` with ``os.replace``
    (atomic on POSIX). On any failure the temporary file is removed and ``path`` keeps its
    previous content. The file gets the permissions ``open(path, "w")`` would give.

    Raises
    ------
    OSError
        When creating, writing or renaming fails.
    """
    path = Path(path)
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp" + path.suffix)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(name, _file_mode())
        os.replace(name, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(name)
        raise
    with contextlib.suppress(OSError):
        dir_fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def _array(value: Any, key: str, ndim: int, source: str,
           limit: float | None = None) -> np.ndarray:
    """``value`` as a finite ``ndim``-D float array, its magnitude at most ``limit`` when
    given (one-line errors naming ``key``)."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelFileError(f"{source}: '{key}' is not a numeric array") from None
    if arr.ndim != ndim:
        raise ModelFileError(f"{source}: '{key}' must be a {ndim}-D array, got shape "
                             f"{arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ModelFileError(f"{source}: '{key}' has a non-finite value")
    if limit is not None and arr.size and np.max(np.abs(arr)) > limit:
        raise ModelFileError(f"{source}: '{key}' has the value {_largest(arr)!r}, beyond the "
                             f"plausible ±{limit:g} of a GRU weight (a damaged or edited "
                             "file)")
    return arr


def _largest(arr: np.ndarray) -> float:
    """The entry of ``arr`` of the largest magnitude."""
    return float(arr.flat[int(np.argmax(np.abs(arr)))])


def _params(doc: dict, source: str) -> dict[str, np.ndarray]:
    """The GRU weights of ``eq:gru``, their shapes checked against each other."""
    params: dict[str, np.ndarray] = {}
    for name in PARAM_NAMES:
        if name not in doc:
            raise ModelFileError(f"{source}: missing array '{name}'")
        params[name] = _array(doc[name], name, 1 if name.startswith("b") else 2, source,
                              limit=WEIGHT_LIMIT)
    n, m = params["W_z"].shape
    p = params["U_o"].shape[0]
    expected = {"W_z": (n, m), "U_z": (n, n), "b_z": (n,), "W_r": (n, m), "U_r": (n, n),
                "b_r": (n,), "W_h": (n, m), "U_h": (n, n), "b_h": (n,), "U_o": (p, n),
                "b_o": (p,)}
    for name, shape in expected.items():
        if params[name].shape != shape:
            raise ModelFileError(f"{source}: '{name}' has shape {params[name].shape}, "
                                 f"expected {shape} (n={n}, m={m}, p={p})")
    return params


def _normalization(doc: dict, source: str, m: int, p: int) -> dict[str, np.ndarray]:
    """The ``normalization`` object: offsets and non-zero scales, one entry per signal."""
    norm = doc.get("normalization")
    if not isinstance(norm, dict):
        raise ModelFileError(f"{source}: missing object 'normalization'")
    scales: dict[str, np.ndarray] = {}
    for key in NORMALIZATION_KEYS:
        if key not in norm:
            raise ModelFileError(f"{source}: missing 'normalization.{key}'")
        scales[key] = _array(norm[key], f"normalization.{key}", 1, source)
        size = m if key.startswith("u") else p
        if scales[key].shape != (size,):
            raise ModelFileError(f"{source}: 'normalization.{key}' must have {size} "
                                 f"entries, got {scales[key].shape[0]}")
        if key.endswith("scale") and np.any(scales[key] == 0):
            raise ModelFileError(f"{source}: 'normalization.{key}' has a zero entry")
    return scales


def _signals(doc: dict, key: str, count: int, source: str) -> tuple[list[str], list[str]]:
    """The names and units of the ``inputs`` or ``outputs`` list."""
    entries = doc.get(key)
    if not isinstance(entries, list) or len(entries) != count:
        raise ModelFileError(f"{source}: '{key}' must list {count} signals")
    names, units = [], []
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            raise ModelFileError(f"{source}: '{key}[{i}]' needs a string 'name'")
        names.append(entry["name"])
        units.append(str(entry.get("unit", "")))
    return names, units


def _design_entries(doc: dict, source: str, n: int, p: int) -> tuple[Any, ...]:
    """The optional entries: observer gains, ``w_y_bar``, ``training``, the measured
    ``prediction_error`` and the ``certificate`` verdict."""
    L_z = L_r = None
    observer = doc.get("observer")
    if observer is not None:
        if not isinstance(observer, dict) or not {"L_z", "L_r"} <= observer.keys():
            raise ModelFileError(f"{source}: 'observer' must hold 'L_z' and 'L_r'")
        L_z = _array(observer["L_z"], "observer.L_z", 2, source)
        L_r = _array(observer["L_r"], "observer.L_r", 2, source)
        for key, gain in (("L_z", L_z), ("L_r", L_r)):
            if gain.shape != (n, p):
                raise ModelFileError(f"{source}: 'observer.{key}' has shape {gain.shape}, "
                                     f"expected {(n, p)}")
    w_y_bar = doc.get("w_y_bar")
    if w_y_bar is not None and (not isinstance(w_y_bar, int | float) or w_y_bar < 0
                                or not math.isfinite(w_y_bar)):
        raise ModelFileError(f"{source}: 'w_y_bar' must be a non-negative number")
    training = doc.get("training", {})
    if not isinstance(training, dict):
        raise ModelFileError(f"{source}: 'training' must be an object")
    profile = None
    if doc.get("prediction_error") is not None:
        profile = _array(doc["prediction_error"], "prediction_error", 2, source)
        if profile.shape[1] != p or profile.shape[0] < 1 or np.any(profile < 0):
            raise ModelFileError(f"{source}: 'prediction_error' must be a non-negative "
                                 f"array of rows of {p} entries, got shape {profile.shape}")
    certificate = doc.get("certificate")
    if certificate is not None and not isinstance(certificate, dict):
        raise ModelFileError(f"{source}: 'certificate' must be an object")
    return L_z, L_r, w_y_bar, training, profile, certificate
