"""The numerical core's co-simulation adapters: the layer above ``controllers`` and ``cosim``.

:mod:`controllers` is the numerical core (GRU, certificates, observer, FHOCP, MPC law): it
works on arrays in normalised units and knows nothing of co-simulation. :mod:`cosim` is the
co-simulation core (master, FMUs, scenarios, results); it knows controllers only as
:class:`~cosim.core.component.Component` classes named in its registry (:mod:`cosim.core.registry`).
This package turns the one into the other:

- :mod:`cosim.adapters.robust_mpc`: the robust GRU MPC (observer + governor + FHOCP) as the
  ``robust-mpc`` controller;
- :mod:`cosim.adapters.pi`: the decentralised PI baseline as the ``pi`` controller;
- :mod:`cosim.adapters.gru_plant`: the GRU model itself as a plant (``model:FILE``).

The import contracts (``[tool.importlinter]`` in pyproject.toml, checked by
``tests/test_layering.py``) keep it so: ``controllers`` imports nothing of ``cosim`` or of
this package, and the co-simulation core imports neither ``controllers`` nor this package
(only its application modules do: the CLI, :mod:`cosim.api` and the campaigns).
"""
