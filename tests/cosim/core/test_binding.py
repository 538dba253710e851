"""Binding a control problem to a plant FMU (:mod:`cosim.core.binding`): unit conversion through
the FMU's UnitDefinitions and through pint, and the checks, on real FMUs (``Reactor.fmu`` of
:mod:`tests.cosim.units_fmu`, the four-tank)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.core.binding import Wanted, bind, unit_conversion, unit_definitions
from cosim.core.errors import CosimError
from cosim.core.fmu import FmuComponent
from cosim.core.fmu_archive import read_model_description
from cosim.core.varmap import VarMap, load
from tests.cosim import units_fmu


@pytest.fixture(scope="module")
def reactor(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return units_fmu.build(tmp_path_factory.mktemp("reactor"))


@pytest.fixture(scope="module")
def defs(reactor: Path) -> dict:
    return unit_definitions(read_model_description(reactor))


def wanted(**changes: tuple[str, str, str]) -> list[Wanted]:
    """The reactor problem's signals (name -> (variable, unit, role)), with ``changes``."""
    sig = {"F": ("F_in", "L/min", "input"), "Tc": ("Tc", "K", "input"),
           "CA": ("CA", "mol/L", "output"), "T": ("T", "K", "output"), **changes}
    return [Wanted(n, v, u, r, f"reactor.toml:{i}") for i, (n, (v, u, r)) in
            enumerate(sig.items(), start=1)]


# -- unit conversion ----------------------------------------------------------------------------

def test_the_fmus_own_base_units_relate_two_units_it_defines(defs: dict) -> None:
    # "Lpm" is defined by the FMU only (pint does not know it): factor 1/60000 to m3/s
    conv = unit_conversion("Lpm", "m3/s", defs)
    assert conv.via == "fmu"
    assert conv.scale == pytest.approx(1 / 60000, rel=1e-15) and conv.offset == 0.0
    # temperature offsets from the FMU's BaseUnit offsets: K -> degC subtracts 273.15
    conv = unit_conversion("K", "degC", defs)
    assert conv.via == "fmu" and conv.scale == 1.0 and conv.offset == pytest.approx(-273.15)
    back = unit_conversion("degC", "K", defs)
    assert back.scale * (conv.scale * 300.0 + conv.offset) + back.offset == pytest.approx(300.0)


def test_pint_relates_units_the_fmu_does_not_define(defs: dict) -> None:
    # the FMU defines m3/s, not L/min: pint, with the Modelica "m3" read as m**3
    conv = unit_conversion("L/min", "m3/s", defs)
    assert conv.via == "pint"
    assert conv.scale == pytest.approx(1 / 60000, rel=1e-12) and conv.offset == 0.0
    conv = unit_conversion("mol/L", "mol/m3", defs)
    assert conv.via == "pint" and conv.scale == pytest.approx(1000.0, rel=1e-12)
    # offset units, without any FMU: degF -> degC is affine, K -> degC too
    f = unit_conversion("degF", "degC")
    assert f.via == "pint" and f.scale * 212.0 + f.offset == pytest.approx(100.0)
    assert f.scale * 32.0 + f.offset == pytest.approx(0.0, abs=1e-12)
    k = unit_conversion("K", "degC")
    assert k.scale == pytest.approx(1.0) and k.offset == pytest.approx(-273.15)
    # Modelica's product and exponent syntax
    assert unit_conversion("kg.m2", "g.cm2").scale == pytest.approx(1e7)
    assert unit_conversion("s-1", "1/min").scale == pytest.approx(60.0)


def test_one_unit_from_the_fmu_and_one_from_pint(defs: dict) -> None:
    """``Lpm`` only the FMU defines, ``L/h`` only pint knows: related through SI."""
    conv = unit_conversion("L/h", "Lpm", defs)
    assert conv.via == "fmu+pint" and conv.scale == pytest.approx(1 / 60, rel=1e-12)


@pytest.mark.parametrize(("p", "f", "words"), [
    ("K", "mol/m3", "'K' is [temperature] but 'mol/m3' is [substance] / [length] ** 3"),
    ("L/min", "m", "'L/min' is [length] ** 3 / [time] but 'm' is [length]"),
    ("Lpm", "degC", "'Lpm' is m3.s-1 but 'degC' is K"),      # both from the FMU, pint knows
])                                                         # neither "Lpm" ... nor needs to
def test_other_dimensions_are_a_contradiction(defs: dict, p: str, f: str, words: str) -> None:
    with pytest.raises(CosimError) as info:
        unit_conversion(p, f, defs)
    assert info.value.kind == "contradiction" and words in str(info.value)


def test_a_unit_nobody_understands_suggests_a_spelling(defs: dict) -> None:
    with pytest.raises(CosimError) as info:
        unit_conversion("Lpmm", "m3/s", defs)
    assert info.value.kind == "unknown"
    assert "the problem's unit 'Lpmm' is not understood" in str(info.value)
    assert "did you mean 'Lpm'" in str(info.value)             # the FMU's own unit
    with pytest.raises(CosimError, match=r"did you mean 'degC'"):
        unit_conversion("degc", "Lpm", defs)                  # case: pint's spelling
    with pytest.raises(CosimError, match=r'write it like "m3/s"'):
        unit_conversion("qqqxz", "m3/s", defs)


# -- binding the reactor -----------------------------------------------------------------------

def test_bind_renames_and_converts_and_the_component_converts_both_ways(reactor: Path) -> None:
    md = read_model_description(reactor)
    vm = bind(wanted(), md, reactor, source="reactor.toml")
    assert vm.path == Path("reactor.toml")
    f, tc, ca, t = (vm.signals[n] for n in ("F", "Tc", "CA", "T"))
    assert (f.variable, f.unit) == ("F_in", "m3/s") and f.scale == pytest.approx(1 / 60000)
    assert (tc.scale, tc.offset) == (1.0, pytest.approx(-273.15))
    assert ca.scale == pytest.approx(1000.0) and t.offset == pytest.approx(-273.15)
    comp = FmuComponent(reactor, varmap=vm)
    assert {s.name for s in comp.inputs} == {"F", "Tc"}       # the FMU's F_in, by problem name
    comp.setup(0.0)
    try:
        start = comp.get_outputs()
        assert start["CA"] == pytest.approx(0.625) and start["T"] == pytest.approx(296.9, abs=0.01)
        comp.set_inputs({"F": 1.5, "Tc": 310.0})              # L/min, K
        comp.step(0.0, 10.0)
        out = comp.get_outputs()
    finally:
        comp.terminate()
    # the echoes are not problem signals: what the FMU received, in its own units
    assert out["F_echo"] == pytest.approx(1.5 / 60000.0, rel=1e-14)
    assert out["Tc_echo"] == pytest.approx(310.0 - 273.15, rel=1e-14)
    assert out["T"] > start["T"] + 0.5 and start["CA"] < out["CA"] < 0.64  # in K and mol/L


def test_a_plant_named_and_united_as_the_problem_needs_no_map(fmu2_path: Path) -> None:
    sigs = [Wanted("qa", "qa", "m3/s", "input"), Wanted("qb", "qb", "m3/s", "input"),
            Wanted("h1", "h1", "m", "output"), Wanted("h2", "h2", "m", "output")]
    vm = bind(sigs, read_model_description(fmu2_path), fmu2_path)
    assert vm == VarMap.identity()       # the four-tank runs exactly as before


@pytest.mark.parametrize(("changes", "words"), [
    ({"F": ("Fin", "L/min", "input")},
     "reactor.toml:1: input 'F' -> FMU variable 'Fin': Reactor.fmu has no such variable"),
    ({"F": ("V", "L/min", "input")},
     "input 'F' -> FMU variable 'V': the variable is a fixed parameter; a problem input must "
     "be an FMU input or a tunable parameter"),
    ({"F": ("CA", "L/min", "input"), "CA": ("level", "mol/L", "output")},
     "input 'F' -> FMU variable 'CA': the variable is of causality 'output'"),
    ({"CA": ("k0", "mol/L", "output")},
     "output 'CA' -> FMU variable 'k0': the variable is of causality 'parameter'; a problem "
     "output must be an FMU output"),
    ({"CA": ("mode", "mol/L", "output")},
     "output 'CA' -> FMU variable 'mode': the variable is of type 'Integer'"),
    ({"CA": ("CA", "K", "output")},
     "reactor.toml:3: output 'CA' -> FMU variable 'CA': a unit the FMU contradicts: the "
     "problem says 'K', Reactor.fmu declares 'mol/m3'"),
    ({"T": ("level", "K", "output")},
     "a unit the FMU contradicts: the problem says 'K', Reactor.fmu declares 'm'"),
    ({"F": ("F_in", "Lpmm", "input")},
     "reactor.toml:1: input 'F' -> FMU variable 'F_in': the problem's unit 'Lpmm' is not "
     "understood"),
])
def test_each_fault_is_one_line_naming_the_file_signal_and_variable(
        reactor: Path, changes: dict, words: str) -> None:
    with pytest.raises(CosimError) as info:
        bind(wanted(**changes), read_model_description(reactor), reactor)
    msg = str(info.value)
    assert words in msg and "\n" not in msg and msg.startswith("reactor.toml:")


def test_a_tunable_parameter_may_be_a_problem_input(reactor: Path) -> None:
    vm = bind(wanted(F=("k0", "1/min", "input")), read_model_description(reactor), reactor)
    comp = FmuComponent(reactor, varmap=vm)
    comp.setup(0.0)
    try:
        comp.set_inputs({"F": 0.12, "Tc": 300.0})            # 0.12 1/min = 2e-3 1/s
        comp.step(0.0, 10.0)
        assert comp.get_outputs()["k_echo"] == pytest.approx(2e-3, rel=1e-14)
    finally:
        comp.terminate()


def test_a_tunable_parameter_input_with_model_exchange_goes_through_event_mode(
        fmu2_path: Path) -> None:
    """gamma_a as a problem input (ME): the same trajectory as set_parameter gives."""
    sigs = [Wanted("qa", "qa", "m3/s", "input"), Wanted("split", "gamma_a", "1", "input"),
            Wanted("h1", "h1", "m", "output")]
    vm = bind(sigs, read_model_description(fmu2_path), fmu2_path)
    runs = []
    for how in ("input", "parameter"):
        comp = FmuComponent(fmu2_path, interface="me", varmap=vm)
        comp.setup(0.0)
        try:
            for k in range(4):
                if how == "input":
                    comp.set_inputs({"qa": 5e-4, "split": 0.2 + 0.1 * k})
                else:
                    comp.set_inputs({"qa": 5e-4})
                    comp.set_parameter("gamma_a", 0.2 + 0.1 * k)
                comp.step(25.0 * k, 25.0)
            runs.append(comp.get_outputs())
        finally:
            comp.terminate()
    assert runs[0] == runs[1] and runs[0]["h1"] != pytest.approx(0.65, abs=1e-3)


# -- a variable map first -----------------------------------------------------------------------

def test_the_map_takes_precedence_and_a_rename_only_entry_is_converted_by_units(
        reactor: Path, tmp_path: Path) -> None:
    path = tmp_path / "r.map.toml"
    # F: scale given (taken as is, here deliberately 2x the true factor); Tc: a rename only
    path.write_text('[signals.F]\nvariable = "F_in"\nscale = 3.3333333333333335e-05\n'
                    '[signals.Tc]\nvariable = "Tc"\nunit = "degC"\n')
    md = read_model_description(reactor)
    vm = bind(wanted(F=("nothing", "L/min", "input")), md, reactor, load(path))
    assert vm.path == path
    assert vm.signals["F"].scale == 3.3333333333333335e-05          # the map's
    assert vm.signals["Tc"].offset == pytest.approx(-273.15)         # from the units
    assert vm.signals["CA"].scale == pytest.approx(1000.0)           # the problem's binding
    # a map entry that contradicts the FMU is the map's fault, named with the map
    path.write_text('[signals.Tc]\nvariable = "Tc"\nunit = "K"\n')
    with pytest.raises(CosimError, match=r"r.map.toml: signal 'Tc' -> variable 'Tc': unit "
                                         "mismatch: the map expects 'K', the FMU declares "
                                         "'degC'"):
        bind(wanted(), md, reactor, load(path))
    # a map entry and a problem signal on one variable
    path.write_text('[signals.Fx]\nvariable = "F_in"\n')
    with pytest.raises(CosimError, match=r"input 'F' -> FMU variable 'F_in': the variable map "
                                         ".* binds that variable to signal 'Fx' already"):
        bind(wanted(), md, reactor, load(path))
