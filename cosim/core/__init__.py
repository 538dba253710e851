"""The co-simulation core: what steps a plant and a controller in lockstep and records it.

The master and its loop (:mod:`cosim.core.master`, :mod:`cosim.core.loop`), the components
(:mod:`cosim.core.component`, the plant FMU :mod:`cosim.core.fmu`, its worker process
:mod:`cosim.core.isolated`, the sensor), scenarios, variable maps and the binding to a control
problem, results, KPIs, figures, the regression comparison, data generation and logged data,
atomic writes and interrupts. It knows controllers only through :mod:`cosim.core.registry` and
imports nothing of the numerical core (``controllers``), of its adapters (``cosim.adapters``)
or of the applications that stand on it (:mod:`cosim.api`, :mod:`cosim.cli`,
:mod:`cosim.commands`, :mod:`cosim.campaign`): the import contracts in ``pyproject.toml``,
checked by ``tests/test_layering.py``, hold the folder to that.
"""
