"""Run any FMI 2.0 or 3.0 FMU (Co-Simulation or Model Exchange) as a :class:`Component`.

fmpy loads the FMU's native library into this process; an FMU is native code that may
crash, so :mod:`cosim.core.isolated` offers the same component in a worker process.

Signals are the FMU's real-valued inputs and outputs under their project names (a
:class:`~cosim.core.varmap.VarMap` renames and converts them; without one, the FMU's names are
used as they are). Value references are looked up once; per-step calls reuse preallocated
ctypes buffers.

An FMU call that fails raises :class:`~cosim.core.errors.FmuError` (a
:class:`~cosim.core.errors.SimulationFailed`) carrying the FMI status it returned. The archive
and the modelDescription are read by :mod:`cosim.core.fmu_archive`; the FMU's log messages are
routed by :mod:`cosim.core.fmu_log`; Model Exchange is integrated by :mod:`cosim.core.fmu_me`.

Several components may live in one process and be stepped from several threads at once (a
campaign worker with two threads): each has its own instance, extracted folder and buffers;
loading a library is serialised (:data:`_LOAD_LOCK`), since fmpy changes the process's
working folder to do it.
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import os
import shutil
import tempfile
import threading
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from cosim.core import fmu_log
from cosim.core.component import Capability, Component, Signal
from cosim.core.errors import CosimError, FmuError
from cosim.core.fmu_archive import check_binary, read_model_description, safe_extract
from cosim.core.fmu_me import ModelExchange
from cosim.core.varmap import VarMap, variable_unit

__all__ = ["FmuComponent", "libraries_loaded"]

_REAL_TYPES = ("Real", "Float64")
#: FMU objects whose libraries stay loaded until the process ends (never dlclose'd).
_KEEP_LOADED: list[Any] = []
#: Numbers the instances of this process (FMU log messages are routed by instance name;
#: ``next()`` on a count is atomic, so two threads never get the same number).
_INSTANCE_NUMBERS = itertools.count(1)
#: Held while fmpy loads an FMU's library (it changes the process's working folder).
_LOAD_LOCK = threading.Lock()
#: FMU libraries loaded by this process (under the lock).
_LOADS = [0]


def libraries_loaded() -> bool:
    """Whether this process has loaded an FMU's library (they stay loaded until it exits)."""
    return _LOADS[0] > 0


class FmuComponent(Component):
    """A plant (or any block) implemented by an FMU.

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file (FMI 2.0 or 3.0).
    name : str
        Component name (prefix of recorded signals).
    interface : {"cs", "me"}
        Co-Simulation (the FMU's own solver) or Model Exchange (fmpy's CVode).
    start_values : dict, optional
        FMU variable (or map signal) → value, applied before initialisation.
    varmap : VarMap, optional
        Renames/converts signals (see :mod:`cosim.core.varmap`).
    rtol : float
        CVode relative tolerance for Model Exchange.
    unpack_dir : str or Path, optional
        An existing empty folder to extract the archive into; its owner removes it (the
        isolated worker's parent does, so that nothing is left behind when the worker dies).
        Default: a new ``cosim-fmu-*`` temporary folder removed by :meth:`terminate`.

    Notes
    -----
    Construction only reads the modelDescription; :meth:`setup` extracts the archive and
    loads the native code.
    """

    direct_feedthrough = False
    #: scenarios set its tunable parameters while it runs; the signals a run wires to it
    #: are checked against its modelDescription before the first step
    capabilities = frozenset({Capability.TUNABLE, Capability.SIGNAL_CHECK})

    def __init__(self, path: str | Path, name: str = "plant", interface: str = "cs",
                 start_values: Mapping[str, float] | None = None,
                 varmap: VarMap | None = None, rtol: float = 1e-8,
                 unpack_dir: str | Path | None = None) -> None:
        self.path = Path(path)
        self.unpack_dir = None if unpack_dir is None else Path(unpack_dir)
        self.name = name
        if interface not in ("cs", "me"):
            raise CosimError(f"{self.path}: unknown interface '{interface}' (use cs or me)")
        self.interface = interface
        self.varmap = varmap or VarMap.identity()
        self.rtol = rtol
        self.md = read_model_description(self.path)
        self.fmi_version = self.md.fmiVersion
        if not (self.fmi_version == "2.0" or self.fmi_version.startswith("3.")):
            raise CosimError(f"{self.path}: FMI {self.fmi_version} is not supported "
                             "(FMI 2.0 and 3.0 are)")
        kind = self.md.coSimulation if interface == "cs" else self.md.modelExchange
        if kind is None:
            other = "me" if interface == "cs" else "cs"
            raise CosimError(f"{self.path}: the FMU has no "
                             f"{'Co-Simulation' if interface == 'cs' else 'Model Exchange'} "
                             f"interface (try --interface {other})")
        self.model_identifier = kind.modelIdentifier
        self.variables = {v.name: v for v in self.md.modelVariables}
        real = [v for v in self.md.modelVariables if v.type in _REAL_TYPES and not v.shape]
        sig = self.varmap.signal_of
        self.inputs = tuple(Signal(sig(v.name), variable_unit(v) or "", v.description or "")
                            for v in real if v.causality == "input")
        self.outputs = tuple(Signal(sig(v.name), variable_unit(v) or "", v.description or "")
                             for v in real if v.causality == "output")
        self.tunables = tuple(sig(v.name) for v in real
                              if v.causality == "parameter" and v.variability == "tunable")
        self.parameters = tuple(sig(v.name) for v in real if v.causality == "parameter")
        self._tunable_set = frozenset(self.tunables)
        self.start_values = dict(start_values or {})
        self._out_names = [s.name for s in self.outputs]
        self._out_maps = [self.varmap.lookup(n) for n in self._out_names]
        self._fmu: Any = None
        self._me: ModelExchange | None = None
        self._tmpdir: Path | None = None
        self._log: deque[str] = deque(maxlen=20)
        self._instance_name = ""
        self._dirty = False
        self._t = 0.0
        self._failed = False
        self._fatal = False

    @property
    def where(self) -> str:
        """Messages name the FMU by its file."""
        return str(self.path)

    # -- name resolution ----------------------------------------------------------------------
    def variable_of(self, signal: str) -> Any:
        """The fmpy ModelVariable behind a project signal or FMU variable name."""
        m = self.varmap.lookup(signal)
        var = self.variables.get(m.variable)
        if var is None:
            var = self.variables.get(signal)
        if var is None:
            raise CosimError(f"{self.path}: no variable '{signal}'")
        return var

    def settable(self, at_start: bool = False) -> set[str]:
        """Names a scenario may set: inputs and tunable (or, at start, all) parameters."""
        names = {s.name for s in self.inputs}
        names |= set(self.parameters if at_start else self.tunables)
        # a mapped variable may also be named as the FMU names it (then in FMU units)
        names |= {m.variable for m in self.varmap.signals.values() if m.signal in names}
        return names

    def check_signals(self, inputs: list[str], outputs: list[str],
                      units: Mapping[str, str] | None = None) -> None:
        """Check the signals a run wires to this FMU, and every entry of its variable map.

        See :meth:`VarMap.check`: an entry the run does not use is checked too (its variable
        must exist, with a usable causality, a real type and the unit the map declares).

        Raises
        ------
        CosimError
            One line naming the map file (or this FMU), the signal and the variable.
        """
        self.varmap.check(self.variables, inputs, outputs, units, fmu=str(self.path))

    # -- life cycle ---------------------------------------------------------------------------
    @contextlib.contextmanager
    def _guard(self, what: Callable[[], str]) -> Iterator[None]:
        """Run FMU calls: a failure, an FMI status check's included, becomes the
        :class:`FmuError` of :meth:`_fail` naming ``what()``; the project's own
        :class:`CosimError` (a bad name, a bad value) passes unchanged."""
        try:
            yield
        except FmuError as exc:  # a status check (a CosimError, but raised by the FMU)
            raise self._fail(what(), exc) from None
        except CosimError:
            raise
        except Exception as exc:
            raise self._fail(what(), exc) from None

    def _fail(self, what: str, exc: BaseException) -> FmuError:
        """The :class:`FmuError` for ``exc`` raised by ``what``, with the FMU's recent log.

        The FMI status comes from ``exc`` (an :class:`FmuError` of :meth:`_check`, or
        fmpy's ``FMICallException``); after a fatal one the instance is not even freed.
        """
        self._failed = True
        status = getattr(exc, "status", None)
        status = status if isinstance(status, int) else None
        if status == FmuError.FATAL:
            self._fatal = True
        log = f" (FMU log: {' | '.join(self._log)})" if self._log else ""
        msg = " ".join(str(exc).split()) + log
        if self._tmpdir is not None:   # the extracted archive, as the FMU's own folder
            msg = msg.replace(str(self._tmpdir), f"<{self.path.name}>")
        return FmuError(f"{self.path.name}: {what} failed: {msg}",
                        function=str(getattr(exc, "function", "") or ""), status=status)

    def setup(self, t0: float, stop_time: float | None = None) -> None:
        """Extract, load, instantiate and initialise the FMU at ``t0``."""
        from fmpy import fmi2, fmi3

        self._tmpdir = (self.unpack_dir if self.unpack_dir is not None
                        else Path(tempfile.mkdtemp(prefix="cosim-fmu-")))
        safe_extract(self.path, self._tmpdir)
        self._instance_name = f"{self.name}{next(_INSTANCE_NUMBERS)}"
        fmu_log.attach(self._instance_name, self._log)
        fmi3_ = self.fmi_version.startswith("3.")
        cls = {("2", "cs"): fmi2.FMU2Slave, ("2", "me"): fmi2.FMU2Model,
               ("3", "cs"): fmi3.FMU3Slave, ("3", "me"): fmi3.FMU3Model}[
                   ("3" if fmi3_ else "2", self.interface)]
        guid = self.md.instantiationToken if fmi3_ else self.md.guid
        check_binary(self.path, self._tmpdir, self.model_identifier, fmi3_)
        # fmpy changes the process's working folder into the binaries folder to load the
        # library (and does not change back when loading fails; that folder is deleted by
        # terminate()): one load at a time in this process, so that a second thread (a
        # campaign worker running two runs) neither saves nor restores the other's folder
        with _LOAD_LOCK:
            cwd = os.getcwd()
            try:
                self._fmu = cls(guid=guid, unzipDirectory=str(self._tmpdir),
                                modelIdentifier=self.model_identifier,
                                instanceName=self._instance_name)
                _LOADS[0] += 1
            except Exception as exc:
                # nothing has run yet: a binary that does not load is a bad FMU (exit 2)
                msg = " ".join(str(exc).replace(str(self._tmpdir), "<fmu>").split())
                raise CosimError(f"{self.path}: cannot load the FMU's binary: {msg}") from None
            finally:
                os.chdir(cwd)
        self._fmi3 = fmi3_
        try:
            if fmi3_:
                self._fmu.instantiate(logMessage=fmu_log.fmi3_logger(self._instance_name),
                                      loggingOn=True)
            else:
                self._fmu.instantiate(callbacks=fmu_log.fmi2_callbacks(), loggingOn=True)
        except Exception as exc:
            # nothing has run: an FMU that refuses to instantiate (its resources damaged,
            # a wrong token) is a bad FMU (exit 2)
            raise CosimError(str(self._fail("instantiation", exc))) from None
        self._prepare_buffers()
        with self._guard(lambda: f"initialisation at t={t0!r}"):
            if not fmi3_:
                self._fmu.setupExperiment(startTime=t0)
        self._set_start_values()
        with self._guard(lambda: f"initialisation at t={t0!r}"):
            if fmi3_:
                self._fmu.enterInitializationMode(startTime=t0)
            else:
                self._fmu.enterInitializationMode()
            self._fmu.exitInitializationMode()
            if self.interface == "me":
                self._me = ModelExchange(self._fmu, self.md, fmi3_, t0, self.rtol)
        self._t = t0

    def _set_start_values(self) -> None:
        """Set :attr:`start_values`; a value the FMU refuses is bad input (nothing has run):
        a :class:`CosimError` naming it, with the FMU's reason from its log."""
        for key, value in self.start_values.items():
            try:
                self._set_var(key, value)
            except FmuError as exc:
                raise CosimError(str(self._fail(f"setting {key} = {value!r}", exc))) from None

    def _raw(self, fname: str) -> Any:
        """The FMU's C function as a bare ctypes function (no argument conversion).

        The hot path passes ctypes instances built once (pointers to preallocated buffers),
        which skips fmpy's per-call wrapper and ctypes' argument conversion.
        """
        addr = ctypes.cast(self._fmu._functions[fname], ctypes.c_void_p).value
        return ctypes.CFUNCTYPE(ctypes.c_int)(addr)

    @staticmethod
    def _check(fname: str, status: int) -> None:
        """Raise :class:`FmuError` when ``fname`` returned worse than a warning."""
        if status > 1:  # fmi2Warning = fmi3Warning = 1
            labels = fmu_log.STATUS_LABELS
            label = labels[status] if status < len(labels) else "?"
            raise FmuError(f"{fname} failed with status {status} ({label})", fname, status)

    def _prepare_buffers(self) -> None:
        n = len(self._out_names)
        vrs = [self.variable_of(s).valueReference for s in self._out_names]
        self._out_vr = (ctypes.c_uint32 * n)(*vrs)
        self._out_val = (ctypes.c_double * n)()
        self._out_identity = all(m.scale == 1.0 and m.offset == 0.0 for m in self._out_maps)
        self._comp_p = ctypes.c_void_p(self._fmu.component)
        size_t, addr = ctypes.c_size_t, ctypes.addressof
        out_args = [self._comp_p, ctypes.c_void_p(addr(self._out_vr)), size_t(n),
                    ctypes.c_void_p(addr(self._out_val))]
        if self._fmi3:
            out_args.append(size_t(n))
            self._cget, self._cset = self._raw("fmi3GetFloat64"), self._raw("fmi3SetFloat64")
            self._get_name, self._set_name = "fmi3GetFloat64", "fmi3SetFloat64"
        else:
            self._cget, self._cset = self._raw("fmi2GetReal"), self._raw("fmi2SetReal")
            self._get_name, self._set_name = "fmi2GetReal", "fmi2SetReal"
            if self.interface == "cs":
                self._cdo_step = self._raw("fmi2DoStep")
        self._out_args = tuple(out_args)
        self._set_plans: dict[tuple[str, ...], tuple[Any, tuple, list[Any]]] = {}

    def _instance(self) -> None:
        """Raise unless the FMU is instantiated: the raw calls below pass its instance's
        address, which :meth:`terminate` frees."""
        if self._fmu is None:
            raise RuntimeError("no FMU instance (before setup() or after terminate())")

    def _get(self) -> None:
        self._instance()
        status = self._cget(*self._out_args)
        if status > 1:
            self._check(self._get_name, status)

    def _plan(self, names: tuple[str, ...]) -> tuple[Any, tuple, list[Any]]:
        """Buffer, call arguments and converters for setting ``names`` in one call."""
        plan = self._set_plans.get(names)
        if plan is None:
            vrs = []
            for name in names:
                var = self.variable_of(name)
                if var.type not in _REAL_TYPES:
                    raise CosimError(f"{self.path}: variable '{var.name}' is not real-valued")
                vrs.append(var.valueReference)
            k = len(names)
            vr, buf = (ctypes.c_uint32 * k)(*vrs), (ctypes.c_double * k)()
            args = [self._comp_p, ctypes.c_void_p(ctypes.addressof(vr)), ctypes.c_size_t(k),
                    ctypes.c_void_p(ctypes.addressof(buf))]
            if self._fmi3:
                args.append(ctypes.c_size_t(k))
            maps = [self.varmap.signals.get(name) for name in names]
            plan = (buf, (vr, *args), [m.to_plant if m else None for m in maps])
            self._set_plans[names] = plan
        return plan

    def _set_var(self, name: str, value: float) -> None:
        self._set_many({name: value})

    def _set_many(self, values: Mapping[str, float]) -> None:
        self._instance()
        buf, args, conv = self._plan(tuple(values))
        if any(conv):
            buf[:] = [v if c is None else c(v) for v, c in zip(values.values(), conv, strict=True)]
        else:
            buf[:] = [*values.values()]
        status = self._cset(*args[1:])
        if status > 1:
            self._check(self._set_name, status)

    # -- stepping -----------------------------------------------------------------------------
    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Set inputs by project name (converted through the variable map).

        An input may be a tunable parameter (a problem input bound to one,
        :mod:`cosim.core.binding`): with Model Exchange it is set in Event Mode, as FMI asks.
        """
        with self._guard(lambda: f"setting inputs at t={self._t!r}"):
            if self.interface == "me" and not self._tunable_set.isdisjoint(values):
                self._me.in_event_mode(lambda: self._set_many(values))
            else:
                self._set_many(values)
        self._dirty = True

    def set_parameter(self, name: str, value: float) -> None:
        """Change a tunable parameter (or an input) during the run."""
        if self._fmu is None:
            self.start_values[name] = value
            return
        if self.interface == "me":
            try:
                self._me.in_event_mode(lambda: self._set_var(name, value))
            except Exception as exc:
                raise self._fail(f"setting {name} at t={self._t!r}", exc) from None
            self._dirty = True
        else:
            self.set_inputs({name: value})

    def step(self, t: float, dt: float) -> None:
        """Advance from ``t`` to ``t + dt`` with the inputs held."""
        try:
            self._instance()
            if self.interface == "cs":
                if self._fmi3:
                    _, terminate, early, _ = self._fmu.doStep(t, dt)
                    if terminate or early:
                        raise RuntimeError("the FMU requested termination"
                                           if terminate else "early return")
                else:
                    status = self._cdo_step(self._comp_p, ctypes.c_double(t),
                                            ctypes.c_double(dt), ctypes.c_int(1))
                    if status > 1:
                        self._check("fmi2DoStep", status)
            else:
                self._me.step(t, t + dt, restart=self._dirty)
                self._dirty = False
        except Exception as exc:
            raise self._fail(f"doStep at t={t!r}", exc) from None
        self._t = t + dt

    def get_outputs(self) -> dict[str, float]:
        """Outputs at the current time, by project name."""
        try:
            self._get()
        except Exception as exc:
            raise self._fail(f"reading outputs at t={self._t!r}", exc) from None
        vals = self._out_val[:]
        if self._out_identity:
            return dict(zip(self._out_names, vals, strict=True))
        return {m.signal: m.from_plant(v) for m, v in zip(self._out_maps, vals, strict=True)}

    def terminate(self) -> None:
        """Terminate and free the instance, remove the extracted files (idempotent).

        After an error the FMU is not terminated (FMI forbids it), after a fatal error not
        even freed. The shared library is never unloaded: FMUs that embed an interpreter
        (pythonfmu) leave objects behind that point into it, and unloading is a common
        source of crashes.
        """
        fmu, self._fmu = self._fmu, None
        if fmu is not None:
            if not self._failed:
                with contextlib.suppress(Exception):
                    fmu.terminate()
            if not self._fatal:
                with contextlib.suppress(Exception):
                    free = fmu.fmi3FreeInstance if self._fmi3 else fmu.fmi2FreeInstance
                    free(fmu.component)
            _KEEP_LOADED.append(fmu)
        fmu_log.detach(self._instance_name)
        if self._tmpdir is not None and self.unpack_dir is None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
        self._tmpdir = None
