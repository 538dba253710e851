"""Small FMUs built by other exporters (pythonfmu / pythonfmu3) for the master's tests.

* ``swapin``: a four-tank variant exported by pythonfmu3 (FMI 3.0) with other variable names and
  units: inputs ``Fa``, ``Fb`` [l/min], outputs ``L1``..``L4`` [cm], tunable ``gammaA``.
* ``failing``: an FMI 2.0 (pythonfmu) single tank whose ``do_step`` raises once ``t ≥ 500 s``.
* ``segfault``: the same tank, but ``do_step`` kills its own process with SIGSEGV at
  ``t ≥ 500 s`` (a crashing native FMU, for ``--isolate``).
* ``exits``: ``do_step`` ends its process with ``os._exit(3)`` at ``t ≥ 500 s``.
* ``hang``: ``do_step`` spins in a Python loop for ever at ``t ≥ 500 s``.
* ``native_hang``: ``do_step`` blocks in native code for ever at ``t ≥ 500 s`` (libc
  ``pause()``; in the isolated worker, which ignores signals, nothing wakes it).
* ``nan``: ``do_step`` makes the level ``h1`` NaN at ``t ≥ 500 s``.
* ``slow``: a healthy tank whose every ``do_step`` sleeps 20 ms (a long run, for signals).
* ``crashy``: a healthy tank with a tunable parameter ``crash_at`` [s] (default 1e9): its
  ``do_step`` segfaults once ``t ≥ crash_at`` (a plant that crashes in some draws).

These FMUs run inside a Python host that has pythonfmu's runtime (the project venv).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tests.toml_text import campaign_spec

SWAPIN = '''
import math
from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64, Unit


class QuadTank(Fmi3Slave):
    author = "tests"
    description = "four-tank variant: l/min in, cm out"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.S, self.g = 0.06, 9.81
        self.a = [1.31e-4, 1.51e-4, 9.27e-5, 8.82e-5]
        self.gammaA, self.gammaB = 0.3, 0.4
        self.Fa, self.Fb = 27.0, 33.0
        self.h = [0.65, 0.65, 0.6514, 0.6638]
        self.L1 = self.L2 = self.L3 = self.L4 = 0.0
        self._publish()
        self.register_units([Unit("l/min", m=3, s=-1, factor=1.0 / 60000.0),
                             Unit("cm", m=1, factor=0.01)])
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        for name in ("Fa", "Fb"):
            self.register_variable(Float64(name, causality=Fmi3Causality.input,
                                           variability=Fmi3Variability.continuous,
                                           start=getattr(self, name), unit="l/min"))
        for name in ("L1", "L2", "L3", "L4"):
            self.register_variable(Float64(name, causality=Fmi3Causality.output,
                                           variability=Fmi3Variability.continuous, unit="cm"))
        self.register_variable(Float64("gammaA", causality=Fmi3Causality.parameter,
                                       variability=Fmi3Variability.tunable, start=0.3))

    def _publish(self):
        self.L1, self.L2, self.L3, self.L4 = (100.0 * x for x in self.h)

    def _rhs(self, h, qa, qb):
        s = [ai * math.sqrt(2 * self.g * max(hi, 0.0)) for ai, hi in zip(self.a, h)]
        ga, gb = self.gammaA, self.gammaB
        return [(-s[0] + s[2] + ga * qa) / self.S, (-s[1] + s[3] + gb * qb) / self.S,
                (-s[2] + (1 - gb) * qb) / self.S, (-s[3] + (1 - ga) * qa) / self.S]

    def do_step(self, current_time, step_size):
        qa, qb = self.Fa / 60000.0, self.Fb / 60000.0
        n = max(1, int(round(step_size / 0.5)))
        dt = step_size / n
        h = self.h
        for _ in range(n):
            k1 = self._rhs(h, qa, qb)
            k2 = self._rhs([x + 0.5 * dt * k for x, k in zip(h, k1)], qa, qb)
            k3 = self._rhs([x + 0.5 * dt * k for x, k in zip(h, k2)], qa, qb)
            k4 = self._rhs([x + dt * k for x, k in zip(h, k3)], qa, qb)
            h = [max(x + dt / 6 * (p + 2 * q + 2 * r + w), 0.0)
                 for x, p, q, r, w in zip(h, k1, k2, k3, k4)]
        self.h = h
        self._publish()
        return True
'''

_TANK = '''
import ctypes
import math
import os
import signal
import time
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class {cls}(Fmi2Slave):
    author = "tests"
    description = "single tank that {what} at t >= {at} s"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.qa = 0.0
        self.qb = 0.0
        self.h1 = 0.5
        self.h2 = 0.5
        for name in ("qa", "qb"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("h1", "h2"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        if current_time >= {at}:
{action}
        self.h1 = max(0.0, self.h1 + step_size * (self.qa - 1e-4 * math.sqrt(self.h1)) / 0.06)
        self.h2 = max(0.0, self.h2 + step_size * (self.qb - 1e-4 * math.sqrt(self.h2)) / 0.06)
        return True
'''

#: The single tanks by kind: (class, what it does, from when [s], what ``do_step`` runs then).
_TANKS = {
    "failing": ("Failing", "raises", 500.0, 'raise RuntimeError("tank ruptured")'),
    "segfault": ("Segfault", "segfaults", 500.0, "os.kill(os.getpid(), signal.SIGSEGV)"),
    "exits": ("Exits", "ends its process", 500.0, "os._exit(3)"),
    "hang": ("Hang", "spins for ever", 500.0, "while True:\n    pass"),
    "native_hang": ("NativeHang", "blocks in native code", 500.0, "ctypes.CDLL(None).pause()"),
    "nan": ("Nan", "turns NaN", 500.0, 'self.h1 = float("nan")\nreturn True'),
    "slow": ("Slow", "sleeps 20 ms per step", 0.0, "time.sleep(0.02)"),
}


def _tank(cls: str, what: str, at: object, action: str) -> str:
    """The source of single tank ``cls`` whose ``do_step`` runs ``action`` once ``t >= at``."""
    return _TANK.format(cls=cls, what=what, at=at, action="\n".join(
        " " * 12 + line for line in action.splitlines()))


CRASHY = _tank("Crashy", "segfaults from crash_at", "self.crash_at",
               "os.kill(os.getpid(), signal.SIGSEGV)").replace(
    """        for name in ("h1", "h2"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))""",
    """        for name in ("h1", "h2"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))
        self.crash_at = 1e9
        self.register_variable(Real("crash_at", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))""").replace(
    "from pythonfmu import Fmi2Causality, Fmi2Slave, Real",
    "from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real")

#: Test FMU kinds: (script name, source). The FMU is named after the class.
KINDS = {"swapin": ("quadtank.py", SWAPIN), "crashy": ("crashy.py", CRASHY)} | {
    kind: (f"{cls.lower()}.py", _tank(cls, *rest)) for kind, (cls, *rest) in _TANKS.items()}

MAP = '''\
[signals.qa]
variable = "Fa"
unit = "l/min"
scale = 60000.0

[signals.qb]
variable = "Fb"
unit = "l/min"
scale = 60000.0

[signals.h1]
variable = "L1"
unit = "cm"
scale = 100.0

[signals.h2]
variable = "L2"
unit = "cm"
scale = 100.0

[signals.gamma_a]
variable = "gammaA"
'''


def build(kind: str, dest: Path) -> Path:
    """Build one of the test FMUs into ``dest`` and return its path."""
    dest.mkdir(parents=True, exist_ok=True)
    src = KINDS[kind]
    script = dest / src[0]
    script.write_text(src[1])
    if kind == "swapin":
        from pythonfmu3.builder import FmuBuilder
    else:
        from pythonfmu.builder import FmuBuilder
    return Path(FmuBuilder.build_FMU(script, dest=dest))


#: Set-point scenarios of the four-tank stand-ins, by file name: 2,000 s and 2,500 s.
SCENARIOS = {"short.csv": "time,ref.h1,ref.h2\n0,0.6,0.6\n1000,0.7,\n2000,,\n",
             "long.csv": "time,ref.h1,ref.h2\n0,0.6,0.6\n1000,0.7,\n2500,,\n"}
SHORT_SCENARIO = SCENARIOS["short.csv"]


def pi_campaign(folder: Path, plant: Path, draw: Mapping[str, Any], *, file: str,
                scenario: str = "short.csv", **campaign: Any) -> Path:
    """A PI campaign (the diagonal pairing) on the stand-in FMU ``plant``, ``draw`` drawn per
    run, the ``[campaign]`` keys ``campaign``: ``folder/file``, its scenario (a name of
    :data:`SCENARIOS`) written beside; the spec's path."""
    (folder / scenario).write_text(SCENARIOS[scenario])
    return campaign_spec(folder, file=file, scenario=scenario, controller="pi", plant=plant,
                         options={"pairing": "diagonal"}, draw=draw, **campaign)


def crashy_campaign(folder: Path, pyfmu_dir: Path, runs: int, seed: int) -> Path:
    """A PI campaign on the Crashy FMU (``folder/crashy.toml`` and its ``short.csv``) whose
    draws segfault at t = 300 s or never (``plant.crash_at``); the spec's path."""
    return pi_campaign(folder, pyfmu_dir / "Crashy.fmu",
                       {"plant.crash_at": {"choice": [300.0, 1e9]}}, file="crashy.toml",
                       runs=runs, seed=seed)
