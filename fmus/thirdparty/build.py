"""Build the third-party example plant ``QuadrupleTank.fmu`` with pythonfmu's builder.

Usage::

    python fmus/thirdparty/build.py --out DIR      # writes DIR/QuadrupleTank.fmu

The FMU is never committed: tests build it into a temporary folder. It is an FMI 2.0
Co-Simulation FMU whose model is the Python class in ``quadruple_tank.py``; it runs in a Python
host with pythonfmu installed (the project's venv).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCRIPT = HERE / "quadruple_tank.py"
#: The variable map that goes with the FMU (project signals -> FMU variables and units).
MAP = HERE / "quadruple_tank.map.toml"
FMU_NAME = "QuadrupleTank.fmu"


def build(out_dir: Path) -> Path:
    """Build ``out_dir/QuadrupleTank.fmu`` and return its path."""
    from pythonfmu.builder import FmuBuilder

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = FmuBuilder.build_FMU(SCRIPT, dest=out_dir / FMU_NAME)
    return Path(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("fmus/build/thirdparty"),
                        help="output folder (default: fmus/build/thirdparty)")
    args = parser.parse_args(argv)
    print(build(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
