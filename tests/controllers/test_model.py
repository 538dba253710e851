"""Model file (``controllers/models/*.json``): round trip and one-line errors."""

from __future__ import annotations

import functools
import json
import math
import operator

import numpy as np
import pytest

from controllers.identification import training
from controllers.model import GRUModel, ModelFileError
from tests.fourtank_problem import FOURTANK


def make_model(seed: int = 0) -> GRUModel:
    p = training.init_params(5, 2, 2, seed)
    return training.build_model(p, FOURTANK, {"seed": seed, "note": "test"}, w_y_bar=0.05)


def write(tmp_path, doc, name="m.json"):
    path = tmp_path / name
    path.write_text(json.dumps(doc, indent=1))
    return path


def test_round_trip_keeps_every_value(tmp_path):
    model = make_model()
    model.L_z = np.full((5, 2), 0.01)
    model.L_r = np.full((5, 2), -0.02)
    path = tmp_path / "m.json"
    model.save(path)
    back = GRUModel.load(path)
    for k, v in model.params.items():
        assert np.array_equal(back.params[k], v), k
    for k in ("u_offset", "u_scale", "y_offset", "y_scale"):
        assert np.array_equal(getattr(back, k), getattr(model, k))
    assert np.array_equal(back.L_z, model.L_z) and np.array_equal(back.L_r, model.L_r)
    assert back.w_y_bar == 0.05 and back.Ts == 25.0
    assert back.input_names == ["qa", "qb"] and back.output_names == ["h1", "h2"]
    assert back.training["seed"] == 0
    assert (back.n, back.m, back.p) == (5, 2, 2)


def test_normalization_maps_saturation_box_to_unit_box():
    model = make_model()
    lo = np.array([b[0] for b in FOURTANK.input_bounds])
    hi = np.array([b[1] for b in FOURTANK.input_bounds])
    assert np.allclose(model.normalize_u(lo), -1) and np.allclose(model.normalize_u(hi), 1)
    assert np.allclose(model.normalize_y([0.0, 2.0]), [-1, 1])
    q = np.array([3e-4, 7e-4])
    assert np.allclose(model.denormalize_u(model.normalize_u(q)), q)


def test_bad_json_names_line_and_column(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{\n "W_z": [[1, 2],\n  oops]\n}\n')
    with pytest.raises(ModelFileError, match=r"bad\.json:3:3: invalid JSON"):
        GRUModel.load(path)


def test_missing_file(tmp_path):
    with pytest.raises(ModelFileError, match="cannot read model file"):
        GRUModel.load(tmp_path / "nope.json")


#: An edited or damaged model file: the place changed (keys and indices), the value put
#: there (:data:`DELETE`: the key removed), the message that refuses it by name.
DELETE = object()
DAMAGED = {
    "missing array": (("U_h",), DELETE, "missing array 'U_h'"),
    "wrong shape": (("U_r",), [[0.0] * 5] * 4,
                    r"'U_r' has shape \(4, 5\), expected \(5, 5\)"),
    # json.dumps writes NaN, json.loads reads it back
    "nan value": (("b_h", 2), math.nan, "'b_h' has a non-finite value"),
    # a weight far beyond what training gives: refused as the controller FMU's data file
    # refuses it
    "absurd weight": (("U_h", 1, 3), -2e6, r"'U_h' has the value -2000000\.0, beyond the "
                                           r"plausible ±1e\+06 of a GRU weight"),
    "missing normalization": (("normalization",), DELETE, "missing object 'normalization'"),
    "zero scale": (("normalization", "u_scale"), [1.0, 0.0],
                   "'normalization.u_scale' has a zero entry"),
    "short offset": (("normalization", "y_offset"), [1.0],
                     "'normalization.y_offset' must have 2 entries"),
    "text offset": (("normalization", "u_offset"), "abc",
                    "'normalization.u_offset' is not a numeric array"),
}


@pytest.mark.parametrize(("where", "value", "message"), DAMAGED.values(), ids=DAMAGED)
def test_a_damaged_model_file_is_refused_by_name(tmp_path, where, value, message):
    doc = make_model().to_dict()
    *parents, last = where
    target = functools.reduce(operator.getitem, parents, doc)
    if value is DELETE:
        del target[last]
    else:
        target[last] = value
    with pytest.raises(ModelFileError, match=message):
        GRUModel.load(write(tmp_path, doc))


def test_a_model_that_would_not_load_is_not_written(tmp_path):
    path = tmp_path / "m.json"
    model = make_model()
    model.save(path)
    before = path.read_bytes()
    for value in (math.nan, 1e300):
        model.params["W_z"][0, 0] = value
        with pytest.raises(ModelFileError, match="not written, it would not load: the model: "
                                                 "'W_z' has"):
            model.save(path)
        assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_error_messages_are_one_line_and_name_the_file(tmp_path):
    doc = make_model().to_dict()
    doc["W_h"] = [[1.0, "x"]] * 5
    path = write(tmp_path, doc, "weights.json")
    with pytest.raises(ModelFileError) as info:
        GRUModel.load(path)
    assert "\n" not in str(info.value) and "weights.json" in str(info.value)


def test_binary_file_is_a_one_line_error(tmp_path):
    path = tmp_path / "m.json"
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ModelFileError, match=r"m\.json: not a JSON model file \(byte 0 is not "
                                             r"UTF-8\)"):
        GRUModel.load(path)


@pytest.mark.parametrize("version", [99, 0, "1", True])
def test_unknown_format_version_is_refused(tmp_path, version):
    doc = make_model().to_dict()
    doc["version"] = version
    with pytest.raises(ModelFileError, match=r"'version' is .*, this cosim reads version 1"):
        GRUModel.load(write(tmp_path, doc))


def test_boolean_sample_time_is_refused(tmp_path):
    doc = make_model().to_dict()
    doc["Ts"] = True
    with pytest.raises(ModelFileError, match=r"'Ts' must be a positive number, got True"):
        GRUModel.load(write(tmp_path, doc))


@pytest.mark.parametrize("text, message", [
    ("[" * 100_000 + "]" * 100_000, "invalid model file (JSON nested too deeply)"),
    ('{"Ts": ' + "1" * 5000 + "}", "invalid JSON (Exceeds the limit (4300 digits)"),
])
def test_deeply_nested_or_huge_json_is_a_one_line_error(tmp_path, text, message):
    path = tmp_path / "deep.json"
    path.write_text(text)
    with pytest.raises(ModelFileError) as info:
        GRUModel.load(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: {message}") and "\n" not in msg


def test_save_replaces_the_file_in_one_step(tmp_path):
    """save() writes a temporary file and renames it: nothing is left beside the target,
    and a save that cannot complete leaves the previous file byte-identical."""
    path = tmp_path / "m.json"
    path.write_text("previous")
    model = make_model()
    model.save(path)
    assert GRUModel.load(path).training["note"] == "test"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json"]
    assert path.read_text() == model.to_json()
    # the target is a folder: the rename fails, the folder and its content stay as they were
    folder = tmp_path / "dir.json"
    folder.mkdir()
    (folder / "keep").write_text("x")
    with pytest.raises(OSError):
        model.save(folder)
    assert [p.name for p in folder.iterdir()] == ["keep"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.json", "m.json"]


def test_load_records_the_source_file(tmp_path):
    path = tmp_path / "m.json"
    make_model().save(path)
    assert GRUModel.load(path).source == str(path) and make_model().source is None
