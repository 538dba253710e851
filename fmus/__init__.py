"""The plant FMUs' sources, shipped as package data (no Python code lives here).

``fourtank/`` holds the C sources (``model.c``, ``instance.c``, the FMI 2 and FMI 3 glue
``fmi2.c`` and ``fmi3.c``, their headers) and the model descriptions
(``modelDescription2.xml``, ``modelDescription3.xml``, ``buildDescription.xml``) of the
four-tank plant FMU. :mod:`cosim.core.build` (``cosim build-fmu``) finds them through this
package, so they are the same in a source checkout and in an installed wheel, and compiles
them with gcc: into this folder when it is writable (``fmus/FourTank.fmu``,
``fmus/build/``), else into the user cache (``~/.cache/gru-mpc/fmus``).

``thirdparty/`` (a pythonfmu example plant used by the tests) is not part of the package.
"""
