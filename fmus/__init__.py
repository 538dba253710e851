"""The plant FMUs' sources, shipped as package data (no Python code lives here).

Laid out as the Modelica Reference-FMUs are: ``glue/`` holds the FMI glue every C plant model
shares (``instance.c``, the FMI-version-independent layer, under the FMI 2 and FMI 3 adapters
``fmi2.c`` and ``fmi3.c``; ``instance.h`` states the contract a model fulfils), and
``fourtank/`` the four-tank plant's own files (``model.c``, ``model.h``, the model
descriptions ``modelDescription2.xml``, ``modelDescription3.xml``, ``buildDescription.xml``,
its ``problem.toml``). :mod:`cosim.core.build` (``cosim build-fmu``) finds them through this
package, so they are the same in a source checkout and in an installed wheel, and compiles
them with gcc: into this folder when it is writable (``fmus/FourTank.fmu``,
``fmus/build/``), else into the user cache (``~/.cache/gru-mpc/fmus``).

``thirdparty/`` (a pythonfmu example plant used by the tests) is not part of the package.
"""
