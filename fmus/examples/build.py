"""Build the example plants' FMUs with pythonfmu: ``CSTR.fmu``, ``Heater.fmu``,
``HeaterDeadTime.fmu``, ``MixingTank.fmu``, ``Furnace.fmu``, ``FurnaceLoad.fmu``,
``Furnace3.fmu`` and the zoo of the field's benchmark plants: ``WoodBerry.fmu``,
``ShellFractionator.fmu``, ``PHNeutralisation.fmu``, ``VanDeVusse.fmu``, ``SlowThermal.fmu``,
``AirHeater.fmu``.

Usage::

    python fmus/examples/build.py --out DIR [NAME ...]   (names: PLANTS below)

Each FMU (FMI 2.0 Co-Simulation) holds its plant's Python class and the shared
``plant_base.py``; it runs in a Python host with pythonfmu installed (the project's venv).
The control problem of each plant is the ``problem.toml`` beside its script. The FMUs are
never committed: tests and the walk-through build them into a folder of their own.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Plant name -> its script (the FMU is named after the class inside).
PLANTS = {"cstr": HERE / "cstr" / "cstr.py", "heater": HERE / "heater" / "heater.py",
          "heater_dead_time": HERE / "heater_dead_time" / "heater_dead_time.py",
          "mixing_tank": HERE / "mixing_tank" / "mixing_tank.py",
          "furnace": HERE / "furnace" / "furnace.py",
          "furnace_load": HERE / "furnace_load" / "furnace_load.py",
          "furnace3": HERE / "furnace3" / "furnace3.py"}
#: The zoo: the field's benchmark plants, built from their published equations (each
#: folder also holds the plant's ``scenario.csv`` and ``campaign.toml``).
ZOO = ("wood_berry", "shell_fractionator", "ph_neutralisation", "van_de_vusse",
       "slow_thermal", "air_heater")
PLANTS.update({name: HERE / name / f"{name}.py" for name in ZOO})
#: Plant name -> FMU file name.
FMU_NAMES = {"cstr": "CSTR.fmu", "heater": "Heater.fmu",
             "heater_dead_time": "HeaterDeadTime.fmu", "mixing_tank": "MixingTank.fmu",
             "furnace": "Furnace.fmu", "furnace_load": "FurnaceLoad.fmu",
             "furnace3": "Furnace3.fmu", "wood_berry": "WoodBerry.fmu",
             "shell_fractionator": "ShellFractionator.fmu",
             "ph_neutralisation": "PHNeutralisation.fmu", "van_de_vusse": "VanDeVusse.fmu",
             "slow_thermal": "SlowThermal.fmu", "air_heater": "AirHeater.fmu"}


def problem_file(name: str) -> Path:
    """The control problem of plant ``name``."""
    return PLANTS[name].with_name("problem.toml")


def build(name: str, out_dir: Path) -> Path:
    """Build ``out_dir/<FMU>`` of plant ``name`` and return its path."""
    from pythonfmu.builder import FmuBuilder

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    # pythonfmu imports the script to read its description: plant_base must be importable
    added = str(HERE) not in sys.path
    if added:
        sys.path.insert(0, str(HERE))
    try:
        path = FmuBuilder.build_FMU(PLANTS[name], dest=out_dir / FMU_NAMES[name],
                                    project_files={HERE / "plant_base.py"})
    finally:
        if added:
            sys.path.remove(str(HERE))
    return Path(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plants", nargs="*", metavar="PLANT",
                        help=f"which plants, of {', '.join(PLANTS)} (default: all)")
    parser.add_argument("--out", type=Path, default=Path("fmus/build/examples"),
                        help="output folder (default: fmus/build/examples)")
    args = parser.parse_args(argv)
    unknown = [p for p in args.plants if p not in PLANTS]
    if unknown:
        parser.error(f"unknown plant {unknown[0]!r} (known: {', '.join(PLANTS)})")
    for name in args.plants or PLANTS:
        print(build(name, args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
