"""Campaign specs and draws: file:line errors, seeded draws that depend on (seed, run) only."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.campaign import draws, spec
from cosim.campaign.report import clopper_pearson_upper
from cosim.cli import main
from cosim.core.errors import CosimError

ROOT = Path(__file__).resolve().parents[3]
SCENARIO = ROOT / "scenarios" / "leak_tank1.csv"
GOOD = f"""\
[campaign]
name = "t"
runs = 5
seed = 3
scenario = "{SCENARIO}"
controller = "robust-mpc"

[controller.options]
du_weight = 0.1

[draw]
"plant.gamma_b" = {{ uniform = [0.37, 0.43] }}
"plant.a2" = {{ normal = [1.51e-4, 3e-6] }}
"sensor.h1.noise" = {{ uniform = [0.0, 0.003] }}
"plant.S" = 0.06

[[variant]]
name = "mpc"

[[variant]]
name = "pi"
controller = "pi"
"""


def write(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_good_spec_parses(tmp_path: Path) -> None:
    s = spec.load(write(tmp_path, GOOD))
    assert (s.name, s.runs, s.seed, s.scenario) == ("t", 5, 3, SCENARIO)
    assert [d.key for d in s.draws] == ["plant.gamma_b", "plant.a2", "sensor.h1.noise",
                                        "plant.S"]
    assert s.draws[3] == spec.Distribution("plant.S", "constant", (0.06,))
    mpc, pi = s.variants
    assert mpc.controller == "robust-mpc" and mpc.options == {"du_weight": 0.1}
    assert pi.controller == "pi" and pi.options == {}


@pytest.mark.parametrize(("edit", "line", "message"), [
    (("runs = 5", "runs = 0"), 3, "runs = 0: expected a positive integer"),
    (("runs = 5", "runs = 2.5"), 3, "runs = 2.5: expected a positive integer"),
    (("seed = 3", "seed = -1"), 4, "seed = -1: expected an integer >= 0"),
    (("name = \"t\"", "name = \"a b\""), 2, "name = 'a b': expected a name"),
    (("controller = \"robust-mpc\"\n", "controller = \"robust-mpc\"\nworkers = 3\n"), 7,
     "[campaign]: unknown key 'workers'"),
    (("[draw]", "[draws]"), 11, "unknown table or key 'draws'"),
    (("uniform = [0.37, 0.43]", "uniform = [0.43, 0.37]"), 12,
     "the low end is above the high end"),
    (("normal = [1.51e-4, 3e-6]", "normal = [1.51e-4, -3e-6]"), 13,
     "normal standard deviation -3e-06 is negative"),
    (("normal = [1.51e-4, 3e-6]", "gauss = [1.51e-4, 3e-6]"), 13,
     "unknown distribution 'gauss'"),
    (("uniform = [0.0, 0.003]", "uniform = [0.0]"), 14, "uniform needs 2 numbers, got 1"),
    (("\"sensor.h1.noise\"", "\"sensor.h1.loud\""), 14,
     "expected a scenario column name"),
    (("\"plant.S\" = 0.06", "plant.S = 0.06"), 15, "quote dotted column names"),
    (("name = \"pi\"", "name = \"mpc\""), 21, "duplicate name 'mpc'"),
    ((f"scenario = \"{SCENARIO}\"", "scenario = \"nowhere.csv\""), 5,
     "scenario = 'nowhere.csv': scenario not found"),
    (("runs = 5\n", ""), 1, "'runs' is missing"),
])
def test_bad_specs_name_file_and_line(tmp_path: Path, edit: tuple[str, str], line: int,
                                      message: str) -> None:
    path = write(tmp_path, GOOD.replace(*edit, 1))
    with pytest.raises(CosimError) as err:
        spec.load(path)
    assert str(err.value).startswith(f"{path}:{line}: "), str(err.value)
    assert message in str(err.value)


def test_invalid_toml_names_the_line(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD.replace("seed = 3", "seed = = 3"))
    with pytest.raises(CosimError, match=rf"^{path}:4: invalid TOML"):
        spec.load(path)


def test_cli_bad_spec_exit_2_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = write(tmp_path, GOOD.replace("runs = 5", "runs = -5"))
    assert main(["campaign", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"cosim campaign: error: {path}:3: runs = -5: expected a positive integer"
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_cli_draw_the_plant_does_not_have_exit_2(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    path = write(tmp_path, GOOD.replace("\"plant.S\" = 0.06", "\"plant.gamma_x\" = 0.3"))
    assert main(["campaign", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"cosim campaign: error: {path}:15: draw 'plant.gamma_x': the plant has no "
                   "input or parameter 'gamma_x'")


def test_draws_depend_on_seed_and_run_only(tmp_path: Path) -> None:
    s = spec.load(write(tmp_path, GOOD))
    ctx = draws.DrawContext.build(s, 0.0)
    first = [draws.draw_run(s, i, ctx) for i in range(5)]
    again = [draws.draw_run(s, i, ctx) for i in reversed(range(5))][::-1]
    assert first == again
    assert len({d.values["plant.gamma_b"] for d in first}) == 5
    assert all(0.37 <= d.values["plant.gamma_b"] <= 0.43 for d in first)
    assert all(d.values["plant.S"] == 0.06 for d in first)
    assert len({d.seed for d in first}) == 5
    # a key's stream is its own: dropping another key does not change it
    fewer = spec.load(write(tmp_path, GOOD.replace(
        "\"plant.a2\" = { normal = [1.51e-4, 3e-6] }\n", ""), "fewer.toml"))
    assert [draws.draw_run(fewer, i, ctx).values["plant.gamma_b"] for i in range(5)] == \
        [d.values["plant.gamma_b"] for d in first]
    other = spec.load(write(tmp_path, GOOD.replace("seed = 3", "seed = 4"), "other.toml"))
    assert draws.draw_run(other, 0, ctx).values != first[0].values


def test_disturbance_steps_are_drawn_per_run_in_their_ranges(tmp_path: Path) -> None:
    from cosim.core import scenario

    text = GOOD + "\n[disturbances]\ncount = 3\nhold = 1000\nTin = [280.0, 300.0]\n"
    s = spec.load(write(tmp_path, text))
    assert s.disturbances == spec.DisturbanceSpec(3, 1000.0, {"Tin": (280.0, 300.0)})
    ctx = draws.DrawContext.build(s, 0.0)
    runs = [draws.draw_run(s, i, ctx) for i in range(4)]
    assert runs == [draws.draw_run(s, i, ctx) for i in range(4)]   # seeded
    for d in runs:
        assert [t for t, _ in d.disturbances] == [0.0, 1000.0, 2000.0]
        assert all(280.0 <= v["Tin"] <= 300.0 for _, v in d.disturbances)
    assert len({d.disturbances[0][1]["Tin"] for d in runs}) == 4
    # the other draws' streams are their own: adding the steps changes none of them
    plain = spec.load(write(tmp_path, GOOD, "plain.toml"))
    assert [draws.draw_run(plain, i, ctx).values for i in range(4)] == [d.values for d in runs]
    # the steps replace the scenario's dist.* columns
    sc = write(tmp_path, "time,ref.h1,dist.Tin\n0,1,290\n500,,295\n4000,,\n", "sc.csv")
    changed = scenario.load(sc).with_changes(disturbances=list(runs[0].disturbances))
    values = [(e.time, v) for e in changed.events for c, v in e.values if c.name == "dist.Tin"]
    assert values == [(t, v["Tin"]) for t, v in runs[0].disturbances]   # the file's 295: gone


@pytest.mark.parametrize(("table", "message"), [
    ("count = 2\nTin = [1.0, 2.0]\n", "[disturbances]: 'hold' (seconds each level is held) is "
     "missing"),
    ("count = 2\nhold = 10\n", "[disturbances]: no disturbance ranges"),
    ("hold = 10\nTin = [2.0, 1.0]\n", "[disturbances] Tin = [2.0, 1.0]: expected a range"),
    ("hold = -1\nTin = [1.0, 2.0]\n", "hold"),
    ("hold = 10\nTin = [1.0, 2.0]\nramp = 3\n", "[disturbances] ramp = 3: expected true"),
])
def test_bad_disturbance_tables_name_the_line(tmp_path: Path, table: str, message: str) -> None:
    path = write(tmp_path, GOOD + "\n[disturbances]\n" + table)
    with pytest.raises(CosimError) as err:
        spec.load(path)
    assert str(err.value).startswith(f"{path}:") and message in str(err.value), str(err.value)


def test_setpoints_default_to_certified_reachable_set_points(tmp_path: Path) -> None:
    from controllers.certification.output_ranges import admissible_ranges

    path = write(tmp_path, GOOD + "\n[setpoints]\ncount = 3\nhold = 1000\n")
    s = spec.load(path)
    ctx = draws.DrawContext.build(s, 0.0)
    model, cert = ctx.model, ctx.cert
    for i in range(10):
        d = draws.draw_run(s, i, ctx)
        assert [t for t, _ in d.setpoints] == [0.0, 1000.0, 2000.0] and d.stop_time == 3000.0
        for _, sp in d.setpoints:
            y = model.normalize_y(np.array([sp["h1"], sp["h2"]]))
            assert cert.failures(y) == []
            cert.reference(y)  # reachable: does not raise
    ranges = {n: (lo, hi) for n, lo, hi in admissible_ranges(cert, model)}
    assert ctx.ranges == ranges


def test_a_certified_first_setpoint_then_the_ranges(tmp_path: Path) -> None:
    """``first = "certified"``: the first set-point from the certified range (a run that starts
    where the FHOCP is feasible), the others over the given ranges; the ranges' draws are
    those of a spec without ``first``."""
    ranges = "[setpoints]\ncount = 3\nhold = 1000\nh1 = [0.1, 1.9]\nh2 = [0.1, 1.9]\n"
    s = spec.load(write(tmp_path, GOOD + "\n" + ranges + "first = \"certified\"\n"))
    plain = spec.load(write(tmp_path, GOOD + "\n" + ranges, "plain.toml"))
    assert s.setpoints.first_certified and not plain.setpoints.first_certified
    ctx = draws.DrawContext.build(s, 0.0)
    outside = 0
    for i in range(10):
        d = draws.draw_run(s, i, ctx)
        y = ctx.model.normalize_y(np.array([d.setpoints[0][1][o] for o in ("h1", "h2")]))
        assert ctx.cert.failures(y) == []
        later = [sp for _, sp in d.setpoints[1:]]
        assert all(0.1 <= v <= 1.9 for sp in later for v in sp.values())
        outside += sum(bool(ctx.cert.failures(ctx.model.normalize_y(
            np.array([sp["h1"], sp["h2"]])))) for sp in later)
    assert outside > 0           # the ranges reach beyond the certified set
    with pytest.raises(CosimError, match="first = 'last'"):
        spec.load(write(tmp_path, GOOD + "\n" + ranges + "first = \"last\"\n", "bad.toml"))


def test_initial_state_offsets_stay_within_the_observer_bound(tmp_path: Path) -> None:
    model = ROOT / "controllers" / "models" / "fourtank_gru.json"
    text = GOOD.replace("controller = \"robust-mpc\"\n",
                        f"controller = \"robust-mpc\"\nplant = \"model:{model}\"\n")
    text = text.replace("\"plant.gamma_b\"", "\"plant.w_y_max\"").split("\"plant.a2\"")[0]
    text += "\n[setpoints]\ncount = 1\nhold = 500\n[initial_state]\noutput_offset = 0.05\n"
    s = spec.load(write(tmp_path, text))
    ctx = draws.DrawContext.build(s, 0.0)
    for i in range(5):
        d = draws.draw_run(s, i, ctx)
        dx = np.array([d.plant_start[f"dx_{j + 1}"] for j in range(ctx.model.n)])
        assert 0 < np.max(np.abs(dx)) <= ctx.cert.e_o0
        first = d.setpoints[0][1]
        assert all(abs(d.plant_start[f"{o}_start"] - first[o]) <= 0.05 for o in first)
        assert len(d.initial_estimate) == ctx.model.n


def test_clopper_pearson_upper_bound() -> None:
    assert clopper_pearson_upper(0, 0) is None
    assert clopper_pearson_upper(5, 5) == 1.0
    # zero events in n trials: 1 - 0.05^(1/n) (about 3/n)
    assert math.isclose(clopper_pearson_upper(0, 200), 1 - 0.05 ** (1 / 200), rel_tol=1e-9)
    # k events: the 95 % quantile of Beta(k + 1, n - k), checked against its definition
    from scipy.stats import binom

    up = clopper_pearson_upper(3, 50)
    assert math.isclose(binom.cdf(3, 50, up), 0.05, rel_tol=1e-6)
