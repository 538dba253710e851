"""Drive the four-tank FMUs through fmpy's low-level API, and an SSP file through libcosim
(helpers for the FMU tests)."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave

LEVELS = ("h1", "h2", "h3", "h4")


def fmi2_callbacks(logger: Callable[[int, str, str], None]):
    """FMI 2 callbacks whose logger calls ``logger(status, category, message)``.

    The FMU pre-formats its messages (escaping '%'), so the Python logger gets the text
    without fmpy's variadic-argument proxy (``addLoggerProxy`` keeps a single global target,
    which would dangle once this callback is garbage-collected).
    """
    from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(
        lambda env, name, status, cat, msg: logger(
            status, cat.decode(), msg.decode().replace("%%", "%")
        )
    )
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    return callbacks


class Plant:
    """An instantiated four-tank FMU (FMI 2 or 3, CS or ME) with name-based access."""

    def __init__(self, path: Path, interface: str = "cs", logger: Callable | None = None):
        self.md = read_model_description(path)
        self.version = int(self.md.fmiVersion[0])
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.unzipdir = extract(path)
        kwargs = {
            "guid": self.md.guid if self.version == 2 else self.md.instantiationToken,
            "unzipDirectory": self.unzipdir,
            "modelIdentifier": self.md.coSimulation.modelIdentifier,
            "instanceName": "plant",
        }
        if self.version == 2:
            cls = FMU2Slave if interface == "cs" else FMU2Model
        else:
            cls = FMU3Slave if interface == "cs" else FMU3Model
        self.fmu = cls(**kwargs)
        self.interface = interface
        self.time = 0.0
        self.initialized = False
        self._instantiate(logger)

    def _instantiate(self, logger: Callable | None) -> None:
        if logger is None:
            self.fmu.instantiate()
            return
        if self.version == 2:
            self._callbacks = fmi2_callbacks(logger)  # keep alive as long as the instance
            self.fmu.instantiate(callbacks=self._callbacks)
        else:
            from fmpy.fmi3 import fmi3LogMessageCallback

            self._log = fmi3LogMessageCallback(
                lambda env, status, cat, msg: logger(status, cat.decode(), msg.decode())
            )
            self.fmu.instantiate(logMessage=self._log)

    def set(self, **values: float) -> None:
        vrs = [self.vr[name] for name in values]
        vals = [float(v) for v in values.values()]
        if self.version == 2:
            self.fmu.setReal(vrs, vals)
        else:
            self.fmu.setFloat64(vrs, vals)

    def get(self, *names: str) -> list[float]:
        vrs = [self.vr[name] for name in names]
        return list(self.fmu.getReal(vrs) if self.version == 2 else self.fmu.getFloat64(vrs))

    def initialize(self, start_time: float = 0.0, **start_values: float) -> None:
        if self.version == 2:
            self.fmu.setupExperiment(startTime=start_time)
            self.set(**start_values)
            self.fmu.enterInitializationMode()
        else:
            self.set(**start_values)
            self.fmu.enterInitializationMode(startTime=start_time)
        self.fmu.exitInitializationMode()
        self.time = start_time
        self.initialized = True

    def do_step(self, step: float) -> None:
        self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=step)
        self.time += step

    def close(self) -> None:
        try:
            if self.initialized:
                self.fmu.terminate()
        finally:
            self.fmu.freeInstance()
            shutil.rmtree(self.unzipdir, ignore_errors=True)   # fmpy's extract: ours to remove


def run_cs(path: Path, u: np.ndarray, ts: float = 25.0, **start_values: float) -> np.ndarray:
    """Co-simulate pump flows ``u`` (n, 2) held over each sample; levels (n + 1, 4)."""
    plant = Plant(path, "cs")
    try:
        plant.initialize(**start_values)
        y = np.empty((len(u) + 1, 4))
        y[0] = plant.get(*LEVELS)
        for k, (qa, qb) in enumerate(u):
            plant.set(qa=qa, qb=qb)
            plant.do_step(ts)
            y[k + 1] = plant.get(*LEVELS)
        return y
    finally:
        plant.close()


def libcosim_run(ssp: Path, plant_fmu: Path, names: Sequence[str], steps: int) -> np.ndarray:
    """The SSP file ``ssp`` run by libcosim (an FMI engine not written here), its instance
    ``plant`` being ``plant_fmu``: that FMU's variables ``names`` after each of ``steps``
    steps, ``(steps, len(names))``."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_ssp_file(str(ssp))
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    index = execution.slave_index_from_instance_name("plant")
    vr = {v.name: v.valueReference for v in read_model_description(str(plant_fmu)).modelVariables}
    out = np.empty((steps, len(names)))
    for k in range(steps):
        assert execution.step()
        out[k] = observer.last_real_values(index, [vr[name] for name in names])
    return out
