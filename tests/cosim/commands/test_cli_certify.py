"""``cosim certify``: table, JSON keys, exit codes, --save, --auto-gain-scale, --data."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from controllers.certification import bounds, gain_design
from controllers.certification import certificates as certs
from controllers.errors import CertificateError
from controllers.model import GRUModel
from cosim.cli import main
from tests.controllers.random_gru import random_gru_model

KEYS = ["sigma_z", "sigma_r", "phi_h", "nu", "rho_s", "c_s", "L_z", "L_r", "nu_o", "rho_o",
        "c_o", "kappa", "L_max", "w_y_bar", "w_bar", "w_L", "a", "b", "e_o0", "e_inf", "s",
        "s_measured", "alpha", "assumption_1", "recursive_feasibility"]


def saved_model(path: Path, w_y_bar: float | None = 0.01,
                edit: Callable[[GRUModel], None] | None = None) -> GRUModel:
    """The random GRU of seed 0, ``edit`` applied to it, with ``w̄_y`` (``None``: none), saved
    at ``path``."""
    m = random_gru_model(0)
    if edit is not None:
        edit(m)
    m.w_y_bar = w_y_bar
    m.save(path)
    return m


@pytest.fixture()
def model_file(tmp_path: Path) -> Path:
    saved_model(tmp_path / "model.json")
    return tmp_path / "model.json"


def test_table_passes_with_exit_0(model_file: Path, capsys) -> None:
    assert main(["certify", str(model_file), "--setpoint", "1.0,1.0"]) == 0
    out = capsys.readouterr().out
    for name in ("nu", "rho_s", "nu_o", "kappa", "L_max", "w_bar", "e_inf", "s", "alpha"):
        assert f"  {name} " in out or f"{name} =" in out
    assert "th:stability-bonassi" in out and "eq:def-alpha" in out
    assert "admissible set-points" in out and "FAILED" not in out


def test_json_keys_and_values(model_file: Path, capsys) -> None:
    assert main(["certify", str(model_file), "--setpoint", "1.0,1.0", "--json", "--law",
                 "paper"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert list(doc) == [*KEYS, "verdict"]
    assert doc["verdict"]["certified"] is True and doc["verdict"]["law"] == "paper"
    m = GRUModel.load(model_file)
    cert = certs.compute_certificate(m, N=15)
    y = m.normalize_y(np.array([1.0, 1.0]))
    assert doc["nu"] == pytest.approx(cert.nu) and doc["alpha"] == pytest.approx(cert.alpha(y))
    assert doc["assumption_1"] is True and doc["recursive_feasibility"] is True
    assert len(doc["a"]) == 16  # i = 0..N with N = 15


def test_json_several_setpoints_is_a_list(model_file: Path, capsys) -> None:
    main(["certify", str(model_file), "--setpoint", "1,1", "--setpoint", "0.8,1.2", "--json",
          "--N", "5", "--law", "paper"])
    docs = json.loads(capsys.readouterr().out)
    assert isinstance(docs, list) and len(docs) == 2
    assert all(list(d) == [*KEYS, "verdict"] for d in docs)
    assert len(docs[0]["b"]) == 6


def test_failing_setpoint_exit_1_names_the_hypothesis(model_file: Path, capsys) -> None:
    """1.99 m is next to the 2 m constraint: outside the tracking law's admissible steady
    outputs, in the user's units, with what would fix it; under the paper's law Assumption 1
    fails."""
    assert main(["certify", str(model_file), "--setpoint", "1.99,1.0"]) == 1
    captured = capsys.readouterr()
    assert "verdict (tracking law): NOT CERTIFIED (usable" in captured.out
    assert ("FAILS: set-point: h1=1.99 m, h2=1 m is outside the set-points that pass "
            "(h1 in [") in captured.out
    assert "    fix: " in captured.out and "h1 in [" in captured.out
    assert "not certified (1 hypothesis check(s) failed)" in captured.err
    assert main(["certify", str(model_file), "--setpoint", "1.99,1.0", "--law", "paper"]) == 1
    captured = capsys.readouterr()
    assert "Assumption 1 (ass:setpoint) fails" in captured.out
    assert "FAILS: set-point: h1=1.99 m" in captured.out


def test_quiet_prints_only_the_verdict_of_an_uncertified_model(model_file: Path,
                                                              capsys) -> None:
    """--quiet (as the other commands have it): the exit status says the verdict; nothing on
    standard output, standard error only for an uncertified model."""
    assert main(["certify", str(model_file), "--setpoint", "1.0,1.0", "--quiet",
                 "--save"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert GRUModel.load(model_file).certificate["certified"] is True   # saved all the same
    assert main(["certify", str(model_file), "--setpoint", "1.99,1.0", "--quiet"]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert "not certified (1 hypothesis check(s) failed)" in captured.err


def unstable_at_its_steady_states(m: GRUModel) -> None:
    """``m`` (a random GRU) made ``ν ≥ 1`` and unstable at its steady states: no terminal
    weight, proved or measured (controllers.certification.measured_terminal)."""
    n = m.params["U_h"].shape[0]
    m.params["b_z"] = np.full(n, -4.0)           # the update gate open: x+ = h
    m.params["U_h"] = 3.0 * np.eye(n)           # h = tanh(3 x + ...): unstable near x = 0
    m.params["W_h"] = np.zeros_like(m.params["W_h"])
    m.params["b_h"] = np.zeros(n)


def test_non_delta_iss_model_is_not_usable_exit_2(tmp_path: Path, capsys) -> None:
    """ν ≥ 1 and unstable at its steady states (no terminal weight, proved or measured): the
    table, the failing hypothesis with its fix, the verdict NOT USABLE and one line on standard
    error (exit 2: cosim run refuses it). ν ≥ 1 alone (U_z scaled by 40, stable at its steady
    states) is usable uncertified: exit 1."""
    def not_delta_iss(m: GRUModel) -> None:
        m.params["U_z"] *= 40

    path = tmp_path / "bad.json"
    m = saved_model(path, edit=not_delta_iss)
    assert main(["certify", str(path)]) == 1
    assert "usable: the robust MPC runs uncertified" in capsys.readouterr().out
    unstable_at_its_steady_states(m)
    m.save(path)
    assert main(["certify", str(path)]) == 2
    captured = capsys.readouterr()
    assert "th:stability-bonassi" in captured.out
    assert "FAILS: stability (δISS, th:stability-bonassi): stability index nu = " in captured.out
    assert captured.err.startswith("cosim certify: not usable: stability index nu = ")
    assert "spectral radius" in captured.err and "fix: " in captured.err
    assert captured.err.count("\n") == 1


def test_bad_model_file_exit_2_one_line(tmp_path: Path, capsys) -> None:
    path = tmp_path / "broken.json"
    path.write_text('{"format": "gru-mpc-model", "W_z": [[1, 2]')
    assert main(["certify", str(path)]) == 2
    err = capsys.readouterr().err
    assert "broken.json" in err and err.count("\n") == 1 and "Traceback" not in err
    assert main(["certify", str(tmp_path / "missing.json")]) == 2
    capsys.readouterr()


def test_bad_setpoint_and_missing_w_y_bar_exit_2(tmp_path: Path, model_file: Path,
                                                 capsys) -> None:
    assert main(["certify", str(model_file), "--setpoint", "1.0"]) == 2
    assert "--setpoint" in capsys.readouterr().err
    path = tmp_path / "now.json"
    saved_model(path, None)
    assert main(["certify", str(path)]) == 2
    assert "--data" in capsys.readouterr().err


def test_auto_gain_scale_and_save(tmp_path: Path, capsys) -> None:
    m = random_gru_model(1)
    m.w_y_bar = 0.15  # large enough that the LP gains fail and must be scaled
    path = tmp_path / "model.json"
    m.save(path)
    points = ["--setpoint", "0.8,0.8", "--setpoint", "1.2,1.2", "--law", "paper"]
    assert main(["certify", str(path), *points]) == 1
    capsys.readouterr()
    assert main(["certify", str(path), *points, "--auto-gain-scale", "--save"]) == 0
    out = capsys.readouterr().out
    assert "(auto)" in out
    saved = GRUModel.load(path)
    Lz, Lr = gain_design.observer_gains_lp(m.params)
    theta = saved.L_z.ravel() @ Lz.ravel() / (Lz.ravel() @ Lz.ravel())
    assert 0 < theta < 1
    assert saved.L_z == pytest.approx(theta * Lz) and saved.L_r == pytest.approx(theta * Lr)
    assert saved.w_y_bar == 0.15
    assert saved.certificate["certified"] is True and saved.certificate["law"] == "paper"
    # the saved gains are the default next time, and they pass
    assert main(["certify", str(path), *points]) == 0
    assert "gains from the model file" in capsys.readouterr().out


def test_explicit_gain_scale(model_file: Path, capsys) -> None:
    assert main(["certify", str(model_file), "--gain-scale", "0", "--json", "--law",
                 "paper"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["kappa"] == 0 and doc["nu_o"] == pytest.approx(doc["nu"])
    assert main(["certify", str(model_file), "--gain-scale", "-1"]) == 2
    capsys.readouterr()


def test_data_option_estimates_w_y_bar(tmp_path: Path, model_file: Path, capsys) -> None:
    from controllers.gru import simulate

    m = GRUModel.load(model_file)
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-1, 1, (60, 2)), 10, axis=0)
    _, xi = simulate(m.params, np.zeros(20), u)
    w = rng.uniform(-0.02, 0.02, xi.shape)
    w[550, 0] = -0.035
    y, up = m.denormalize_y(xi + w), m.denormalize_u(u)
    split = ["train"] * 200 + ["val"] * 200 + ["test"] * 200
    rows = ["time,qa,qb,h1,h2,split"] + [
        f"{25.0 * k},{up[k, 0]:.17g},{up[k, 1]:.17g},{y[k, 0]:.17g},{y[k, 1]:.17g},{split[k]}"
        for k in range(600)]
    data = tmp_path / "data.csv"
    data.write_text("\n".join(rows) + "\n")
    assert main(["certify", str(model_file), "--data", str(data), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["w_y_bar"] == pytest.approx(0.035, abs=1e-4)


def test_plot_writes_a_figure(model_file: Path, tmp_path: Path, capsys) -> None:
    png = tmp_path / "fig" / "cert.png"
    assert main(["certify", str(model_file), "--setpoint", "1,1", "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20000
    assert "figure written" in capsys.readouterr().err


def test_bad_plot_target_exit_2_before_computing(model_file: Path, tmp_path: Path,
                                                 capsys) -> None:
    assert main(["certify", str(model_file), "--plot", str(tmp_path / "alpha.csv")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert "alpha.csv: --plot: unknown figure type '.csv'" in captured.err
    (tmp_path / "blocker").write_text("a file")
    assert main(["certify", str(model_file), "--plot", str(tmp_path / "blocker" / "a.png")]) == 2
    assert "is not a folder" in capsys.readouterr().err


def test_model_with_other_signal_names_names_the_file(tmp_path: Path, capsys) -> None:
    doc = json.loads(json.dumps(random_gru_model(0).to_dict()))
    doc["w_y_bar"] = 0.01
    doc["outputs"][0]["name"] = "H1"
    path = tmp_path / "renamed.json"
    path.write_text(json.dumps(doc))
    assert main(["certify", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"cosim certify: error: {path}: its problem 'fourtank' does not "
                          "match the model: signals")
    assert err.count("\n") == 1


def test_saturated_update_gate_exit_2_naming_sigma_z(tmp_path: Path, capsys) -> None:
    """b_z = 40: σ̄_z rounds to 1, so ν = … /(1 − σ̄_z) is undefined (was ZeroDivisionError)."""
    def saturate(m: GRUModel) -> None:
        m.params["b_z"][:] = 40.0

    path = tmp_path / "saturated.json"
    m = saved_model(path, edit=saturate)
    for extra in ([], ["--json"], ["--auto-gain-scale"], ["--gain-scale", "0.5"]):
        assert main(["certify", str(path), *extra]) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.count("\n") == 1
        assert captured.err.startswith(f"cosim certify: error: {path}: sigma_z (σ̄_z = "
                                       "σ(‖[W_z U_z b_z]‖∞) = σ(")
        assert "rounds to 1" in captured.err and "1 − σ̄_z = 0" in captured.err
    with pytest.raises(CertificateError, match=r"^sigma_z .* rounds to 1"):
        bounds.nu(m.params)


@pytest.fixture()
def no_admissible_setpoint(tmp_path: Path) -> Path:
    """ν, ν_o < 1 but w̄_y = 1.2 > the half-width of the normalised output box: the tightened
    bounds cross and no set-point is admissible."""
    saved_model(tmp_path / "wide.json", 1.2)
    return tmp_path / "wide.json"


def test_empty_admissible_range_exits_1(no_admissible_setpoint: Path, capsys) -> None:
    path = str(no_admissible_setpoint)
    assert main(["certify", path, "--gain-scale", "0", "--law", "paper"]) == 1
    captured = capsys.readouterr()
    assert ("admissible set-points (ass:setpoint and eq:condition-recursive-feasibility): "
            "h1: none; h2: none") in captured.out
    assert ("FAILED: admissible set-points (ass:setpoint and eq:condition-recursive-"
            "feasibility): none for h1, h2") in captured.out
    assert "FAILS: room for set-points: " in captured.out
    assert "set-points that pass: h1: none; h2: none" in captured.out
    assert captured.err.startswith("cosim certify: not certified (1 hypothesis check(s)")
    assert main(["certify", path, "--gain-scale", "0", "--json", "--law", "paper"]) == 1
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert doc["nu"] < 1 and doc["verdict"]["certified"] is False
    assert doc["verdict"]["admissible_setpoints"] == {"h1": None, "h2": None}


@pytest.mark.parametrize("case", ["nu", "admissible"])
def test_save_writes_the_verdict_certified_or_not(case: str, tmp_path: Path,
                                                  no_admissible_setpoint: Path,
                                                  capsys) -> None:
    """--save always writes what was computed: the gains, w̄_y and the verdict, whose
    ``certified`` is false with the reasons. Both models are refused by the robust MPC (ν ≥ 1
    and unstable at its steady states: no terminal weight; a test error wider than the box: no
    admissible output even with the measured tightening): exit 2, the saved ``usable`` false
    with the reason, the verdict NOT USABLE, and ``cosim run`` refusing it in the same
    words."""
    if case == "nu":  # ν ≥ 1 (th:stability-bonassi fails)
        path = tmp_path / "bad.json"
        saved_model(path, edit=unstable_at_its_steady_states)
        extra: list[str] = []
    else:
        path, extra = no_admissible_setpoint, ["--gain-scale", "0"]
    assert main(["certify", str(path), "--save", *extra]) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert f"verdict (certified: false) to {path}" in err
    saved = GRUModel.load(path)
    assert saved.certificate["certified"] is False and saved.L_z is not None
    failing = [f for f in saved.certificate["findings"] if not f["holds"]]
    assert failing and failing[0]["hypothesis"] == (
        "stability (δISS, th:stability-bonassi)" if case == "nu" else "room for set-points")
    assert saved.certificate["usable"] is False
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp file
    assert "NOT USABLE (the robust MPC refuses this model" in captured.out
    why = err.splitlines()[-1].removeprefix("cosim certify: not usable: ")
    assert why == saved.certificate["unusable_reason"]
    assert why.startswith("stability index nu = " if case == "nu" else
                          "no admissible steady output: ")
    assert ("fix: train the model" if case == "nu" else "fix: train it longer") in why
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,,\n")
    gains = ["--option", "gain_scale=0"] if extra else []   # the design certified
    assert main(["run", str(scenario), "--model", str(path), "--out", str(tmp_path / "o"),
                 *gains]) == 2
    assert capsys.readouterr().err == (f"cosim run: error: controller 'mpc': the model is "
                                       f"not usable: {why}\n")


def test_save_on_a_full_disk_keeps_the_model_file(model_file: Path, tmp_path: Path) -> None:
    """A real EFBIG: the process may not write files beyond LIMIT bytes (RLIMIT_FSIZE, with
    SIGXFSZ ignored so that the write fails instead of killing the process)."""
    import os
    import resource
    import signal
    import subprocess

    before = model_file.read_bytes()
    limit = 4096
    assert len(before) > 4 * limit  # the file --save writes is larger than the limit

    def full_disk() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "certify", str(model_file),
                           "--save"], capture_output=True, text=True, env=env,
                          preexec_fn=full_disk, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr == f"cosim certify: failed: {model_file}: cannot write: File too large\n"
    assert model_file.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [model_file.name]
    # without the limit the same command saves the gains
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "certify", str(model_file),
                           "--save"], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert GRUModel.load(model_file).L_z is not None and model_file.read_bytes() != before


def test_deeply_nested_model_file_exit_2_one_line(tmp_path: Path, capsys) -> None:
    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    assert main(["certify", str(path)]) == 2
    assert capsys.readouterr().err == (f"cosim certify: error: {path}: invalid model file "
                                       "(JSON nested too deeply)\n")


def test_plot_replaces_the_figure_atomically(model_file: Path, tmp_path: Path,
                                             capsys) -> None:
    png = tmp_path / "cert.png"
    png.write_bytes(b"old")
    assert main(["certify", str(model_file), "--plot", str(png)]) == 0
    capsys.readouterr()
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cert.png", "model.json"]


# -- set-points by name, --problem, any numbers of signals ----------------------------------------
CSTR_TOML = """[problem]
name = "cstr"
Ts = 15.0

[inputs.F]
unit = "L/min"
min = 2.0
max = 12.0
description = "feed flow"

[inputs.Tc]
unit = "K"
min = 280.0
max = 320.0
description = "coolant temperature"

[outputs.CA]
unit = "mol/L"
min = 0.1
max = 0.9
description = "concentration of A"

[outputs.T]
unit = "K"
min = 300.0
max = 360.0
description = "reactor temperature"
"""


@pytest.fixture()
def cstr_file(tmp_path: Path) -> Path:
    """A 2 × 2 model of another problem (CA [mol/L], T [K], Ts = 15 s) with w̄_y."""
    from tests.controllers.random_gru import other_problem

    m = random_gru_model(3, n=10, problem=other_problem())
    m.w_y_bar = 0.01
    path = tmp_path / "cstr.json"
    m.save(path)
    return path


def test_setpoints_by_name_in_the_problems_units(cstr_file: Path, capsys) -> None:
    """--setpoint CA=…,T=… (any order) is the positional form in the problem's output order;
    the set-point is labelled by name."""
    from controllers.equilibrium import equilibrium_output

    m = GRUModel.load(cstr_file)
    ca, t = (float(v) for v in m.denormalize_y(
        equilibrium_output(m.params, np.array([0.3, -0.2]))[1]))
    outs = []
    for form in (f"CA={ca!r},T={t!r}", f"T={t!r}, CA={ca!r}", f"{ca!r},{t!r}"):
        assert main(["certify", str(cstr_file), "--setpoint", form]) == 0
        outs.append(capsys.readouterr().out)
    assert outs[0] == outs[1] == outs[2]
    assert f"set-point CA={ca:g}, T={t:g}: alpha = " in outs[0]
    assert "CA ∈ [" in outs[0] and "mol/L" in outs[0] and "ū: F=" in outs[0]


@pytest.mark.parametrize(("form", "words"), [
    ("CA=0.6", "no value for T (expected CA=V,T=V)"),
    ("CA=0.6,T=330,CA=0.5", "output 'CA' given twice"),
    ("CA=0.6,h1=1", "no output 'h1' in the problem (outputs: CA, T)"),
    ("CA=0.6,330", "give every output by name (CA=V,T=V) or none"),
    ("CA=x,T=330", "CA='x' is not a number"),
    ("CA=nan,T=330", "not finite: CA=nan"),
    ("0.6", "expected 2 numbers (CA,T), or CA=V,T=V"),
])
def test_bad_named_setpoints_exit_2_one_line(cstr_file: Path, form: str, words: str,
                                             capsys) -> None:
    assert main(["certify", str(cstr_file), "--setpoint", form]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert f"--setpoint {form!r}: {words}" in captured.err


def test_problem_option_agrees_or_exit_2_naming_both(cstr_file: Path, model_file: Path,
                                                     tmp_path: Path, capsys) -> None:
    toml = tmp_path / "cstr.toml"
    toml.write_text(CSTR_TOML)
    assert main(["certify", str(cstr_file), "--problem", str(toml), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["nu"] < 1
    assert main(["certify", str(model_file), "--problem", str(toml)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--problem {toml} contradicts the problem of " in err
    assert str(model_file) in err and "'fourtank'" in err and "'cstr'" in err
    assert main(["certify", str(model_file), "--problem", str(tmp_path / "no.toml")]) == 2
    assert "no.toml: problem file not found" in capsys.readouterr().err


def test_auto_gain_scale_without_a_passing_theta(tmp_path: Path, capsys) -> None:
    """w̄_y = 0.6: ν, ν_o < 1 and the admissible range is not empty, but no θ passes at the 9
    default set-points (the grid at 25/50/75 % of the [0, 2] m boxes). The paper's law: not
    certified (exit 1), the θ = 0 gains and the verdict saved. The tracking law, whose
    observer has zero gains anyway: its terminal radius falls back to the one of the model's
    output map (no default depends on the failed gain design), and it is certified for the
    set-points inside its admissible steady outputs."""
    path = tmp_path / "noisy.json"
    saved_model(path, 0.6)
    assert main(["certify", str(path), "--auto-gain-scale", "--save", "--law", "paper"]) == 1
    captured = capsys.readouterr()
    assert "LP gains × θ = 0 (no θ in [0, 1] passes)" in captured.out
    assert ("FAILED: gain scale: no θ in [0, 1] passes every hypothesis at the 9 default "
            "set-points over the output box") in captured.out
    assert "FAILS: paper law design: gain scale: no θ in [0, 1] passes" in captured.out
    saved = GRUModel.load(path)
    assert saved.certificate["certified"] is False and not np.any(saved.L_z)
    assert main(["certify", str(path), "--auto-gain-scale", "--json", "--law", "paper"]) == 1
    doc = json.loads(capsys.readouterr().out)
    assert doc["kappa"] == 0 and doc["verdict"]["certified"] is False
    from controllers.laws.tracking.law import fallback_alpha_c

    assert main(["certify", str(path), "--auto-gain-scale", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    cert0 = certs.compute_certificate(GRUModel.load(path), N=80, gain_scale=0.0)
    assert doc["tracking"]["alpha_c"] == pytest.approx(fallback_alpha_c(cert0))
    assert doc["verdict"]["certified"] is True


@pytest.mark.parametrize(("m", "p", "grid"), [(1, 1, 3), (3, 2, 9), (2, 3, 27)])
def test_auto_gain_scale_on_the_default_grid_of_any_problem(m: int, p: int, grid: int,
                                                            tmp_path: Path, capsys) -> None:
    """The default set-points are the 3^p grid over the output box; the chosen gains are
    saved; --plot draws the figure for one, two and three outputs."""
    model = random_gru_model(2, n=8, m=m, p=p)
    model.w_y_bar = 0.3
    path = tmp_path / "model.json"
    model.save(path)
    png = tmp_path / "cert.png"
    code = main(["certify", str(path), "--auto-gain-scale", "--save", "--plot", str(png)])
    captured = capsys.readouterr()
    assert code == 0, captured.out + captured.err
    assert "(auto)" in captured.out and f"m={m}, p={p}" in captured.out
    saved = GRUModel.load(path)
    assert saved.L_z.shape == (8, p)
    theta = float(captured.out.split("LP gains × θ = ")[1].split(" ")[0])
    assert 0 < theta < 1   # w̄_y = 0.3: the LP gains fail at the grid's outer points
    targets = [model.normalize_y(np.array(s))
               for s in gain_design.default_setpoints(model.problem)]
    assert len(targets) == grid
    cert = certs.compute_certificate(saved, N=15)
    assert all(cert.ok(y) for y in targets)
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_the_tracking_laws_hypotheses(model_file: Path, capsys) -> None:
    """``--law tracking`` (the default, as robust-mpc's): H3-H6 of docs/design/tracking.md at
    N = 80, in the table and the JSON; a failing one (no admissible steady output) is exit 1
    naming it. With a gain scale of 0 the default alpha_c (the certified design's alpha_min)
    is 0: the fallback radius of the model's output map instead (certified)."""
    assert main(["certify", str(model_file)]) == 0
    out = capsys.readouterr().out
    assert "N=80" in out and "tracking law (zero observer gains): alpha_c = " in out
    assert "Y_s not empty = yes" in out
    assert main(["certify", str(model_file), "--gain-scale", "0"]) == 0
    assert "verdict (tracking law): CERTIFIED" in capsys.readouterr().out
    assert main(["certify", str(model_file), "--law", "tracking", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    h = doc["tracking"]
    assert h["recursive_feasibility"] and h["Ys_nonempty"] and h["alpha_min"] == 0.0
    assert h["alpha_c"] > 0 and h["grid_points_admissible"] > 0
    # at N = 40 a large initial estimation error leaves Y_s empty (at N = 80 ρ_s^N shrinks
    # α_c enough that it does not)
    assert main(["certify", str(model_file), "--law", "tracking", "--e-o0", "1",
                 "--N", "40"]) == 1
    out = capsys.readouterr().out
    assert "FAILS: room for set-points: " in out and "set-points that pass: h1: none" in out
    assert "even an exact model would not pass" in out


def test_certify_takes_the_design_of_the_problems_mpc_table(tmp_path: Path, capsys) -> None:
    """The problem's [mpc] N, Q and R are the design certified (the controller's), under
    the flags given."""
    from cosim.adapters.robust_mpc import RobustMPCController
    from tests.fourtank_problem import with_table

    tuned = with_table(tmp_path, "mpc", 'Q = "outputs"\nN = 40\n')

    def certify(*extra: str) -> dict:
        assert main(["certify", "--json", *extra]) in (0, 1)
        doc = json.loads(capsys.readouterr().out)
        return doc[0] if isinstance(doc, list) else doc

    plain, own = certify(), certify("--problem", str(tuned))
    ctrl = RobustMPCController(problem=tuned)
    assert own["s"] == pytest.approx(ctrl.mpc.cert.s, rel=1e-12) and ctrl.mpc.cert.N == 40
    assert own["s"] != pytest.approx(plain["s"], rel=1e-3)   # Q = U_oᵀU_o + εI, not I
    assert len(own["a"]) == 41 and len(certify("--problem", str(tuned), "--N", "30")["a"]) == 31
