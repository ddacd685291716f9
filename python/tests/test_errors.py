"""Every bad input the command's tests check, from Python.

Each test builds the bad input of one command-line test from the bundled
KR-270 job (``data/kr270``: ``setup.toml``, ``kr270.urdf``,
``measurements.csv``) in pytest's ``tmp_path`` and asserts that the Python
call raises the right exception (``InputError`` for a file or table that
cannot be read, ``CalibrationError`` for the engine's refusals,
``NotACalibrationError`` where the command exits 1 with "not a
calibration", ``ValueError``/``TypeError`` for Python arguments) with a ONE
line message containing the key phrase the command's test asserts; a
warning on the command's stderr is a ``robcal.RobcalWarning`` (readers,
payload rule) or an entry of ``Calibration.warnings`` (the report).

Each test's docstring names the command-line test it mirrors:

- ``tests/cli/input_errors.rs`` (22 tests), every one;
- ``tests/cli/hostile.rs`` (7 tests): the ``import`` subcommands have no
  Python path, ``--max-data-mib`` is ``Job._native.read_measurements(path,
  max_bytes)``, ``--output``/``--plots`` are ``Calibration.write(dir)``;
- ``tests/cli/apply.rs``, the error cases: ``robcal predict``/``compensate``
  are ``Model.predict``/``Model.compensate`` (numpy, SI units), a model
  file is ``Model.load``/``Model.from_json``;
- the clap usage errors are the Python argument checks (``ValueError``).

Then the numpy- and pandas-specific cases (wrong shape, dtype, non-finite
values, empty arrays, rows that do not match between arguments) the
command cannot be given.

"""

from __future__ import annotations

import json
import math
import os
import shutil
import stat
import threading
import warnings
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import pandas as pd
import pytest

import robcal

REPO = Path(__file__).resolve().parents[2]
KR = REPO / "data" / "kr270"
SETUP = KR / "setup.toml"
URDF = KR / "kr270.urdf"
DATA = KR / "measurements.csv"

# Columns of measurements.csv (the command's tests index cells the same way).
COL_LOAD = 3
COL_JOINTS = slice(4, 10)
COL_A3 = 6
COL_X = 10

# The paper's first configuration (deg -> rad), and its load's centre of mass.
Q1 = np.radians([79.2, -20.0, -5.57, 51.0, -97.52, -91.67])
Q3 = np.tile(Q1, (3, 1))
COM = [0.25, 0.0, 0.30]
LOADS3 = [250.0, 250.0, 250.0]


# --------------------------------------------------------------------------
# Helpers


def message(excinfo: pytest.ExceptionInfo, *phrases: str) -> str:
    """The exception's message: one line, containing every phrase."""
    msg = str(excinfo.value)
    assert "\n" not in msg and "\r" not in msg, f"not one line: {msg!r}"
    for p in phrases:
        assert p in msg, f"{p!r} not in {msg!r}"
    return msg


def setup_file(tmp: Path, units: Optional[str] = None, replace: tuple = (), name: str = "setup.toml") -> Path:
    """A copy of the KR-270 setup in ``tmp`` (robot path absolute), its
    ``[units]`` replaced by ``units`` and each ``(from, to)`` of ``replace``
    applied (the command's tests' ``job()``)."""
    text = SETUP.read_text().replace('robot = "kr270.urdf"', f"robot = {json.dumps(str(URDF))}")
    if units is not None:
        text = text.replace('angle = "deg"\nlength = "mm"', units)
    for a, b in replace:
        assert a in text, a
        text = text.replace(a, b)
    p = tmp / name
    p.write_text(text)
    return p


def data_csv(
    tmp: Path,
    edit: Optional[Callable[[int, list], Optional[list]]] = None,
    name: str = "data.csv",
) -> Path:
    """The KR-270 measurements in ``tmp``, each data row passed through
    ``edit(line, cells)`` (line 1-based as in the file; None drops it)."""
    lines = DATA.read_text().splitlines()
    out = [lines[0]]
    for i, line in enumerate(lines[1:]):
        cells = line.split(",")
        if edit is not None:
            cells = edit(i + 2, cells)
        if cells is not None:
            out.append(",".join(cells))
    p = tmp / name
    p.write_text("\n".join(out) + "\n")
    return p


def read(job: robcal.Job, path: Path, via: str) -> robcal.Measurements:
    """The file read by the file reader (``via="path"``), or read by pandas
    and given as a DataFrame named like the file (``via="frame"``)."""
    if via == "path":
        return job.measurements(path)
    pd = pytest.importorskip("pandas")
    return job.measurements(pd.read_csv(path), name=path.name)


def calibrate(setup: Path, data: Path, via: str = "path", **settings) -> robcal.Calibration:
    """``robcal calibrate --setup SETUP --data DATA`` (without the closed
    loop unless asked), the data a path or a DataFrame."""
    settings.setdefault("diagnose", False)
    if via == "path":
        return robcal.calibrate(setup, data, **settings)
    job = robcal.Job.load(setup)
    return job.calibrate(read(job, data, via), **settings)


def urdf_with(tmp: Path, name: str, extra: str) -> Path:
    """The KR-270 URDF with ``extra`` before ``</robot>``."""
    p = tmp / name
    p.write_text(URDF.read_text().replace("</robot>", extra + "</robot>"))
    return p


def setup_with_robot(tmp: Path, robot: Path) -> Path:
    """The KR-270 setup in ``tmp`` with ``robot = ROBOT``."""
    text = SETUP.read_text().replace('robot = "kr270.urdf"', f"robot = {json.dumps(str(robot))}")
    p = tmp / "setup.toml"
    p.write_text(text)
    return p


def listing(d: Path) -> list[str]:
    return sorted(os.listdir(d))


both = pytest.mark.parametrize("via", ["path", "frame"])


@pytest.fixture(scope="module")
def job() -> robcal.Job:
    return robcal.Job.load(SETUP)


@pytest.fixture(scope="module")
def calibration(job) -> robcal.Calibration:
    """``robcal calibrate --no-diagnose`` on the KR-270 job as shipped."""
    return job.calibrate(DATA, diagnose=False)


@pytest.fixture(scope="module")
def model_json(calibration) -> str:
    return calibration.model_json


@pytest.fixture(scope="module")
def model(model_json) -> robcal.Model:
    return robcal.Model.from_json(model_json)


@pytest.fixture
def fifo(tmp_path):
    """A FIFO; should a reader block on it, it is opened for writing and
    closed after 20 s so the reader sees an empty file and the test fails
    instead of hanging (the command's tests' HANG_GUARD)."""
    p = tmp_path / "fifo"
    os.mkfifo(p)

    def unblock():
        try:
            fd = os.open(p, os.O_WRONLY | os.O_NONBLOCK)
            os.close(fd)
        except OSError:
            pass

    guard = threading.Timer(20.0, unblock)
    guard.daemon = True
    guard.start()
    yield p
    guard.cancel()


# --------------------------------------------------------------------------
# tests/cli/input_errors.rs


@both
def test_degrees_read_as_radians_is_an_error_naming_the_cell(tmp_path, via):
    """mirrors cli::input_errors::degrees_read_as_radians_is_an_error_naming_the_cell"""
    setup = setup_file(tmp_path, units='angle = "rad"\nlength = "mm"')
    data = data_csv(tmp_path)
    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data, via)
    message(e, "data.csv:2: column 'a1': 79.2 rad is beyond ±2π", "is the column in degrees?")


def test_radians_read_as_degrees_warns(tmp_path):
    """mirrors cli::input_errors::radians_read_as_degrees_warns_on_stderr:
    the reader's warning, then the engine's refusal (the positions do not
    match the nominal robot read in degrees)."""
    setup = setup_file(tmp_path)

    def to_rad(_, c):
        c[COL_JOINTS] = [repr(math.radians(float(v))) for v in c[COL_JOINTS]]
        return c

    data = data_csv(tmp_path, to_rad)
    says = "data.csv: every revolute joint value is within ±π"
    job = robcal.Job.load(setup)
    with pytest.warns(robcal.RobcalWarning, match="are the joint columns in radians\\?") as rec:
        m = job.measurements(data)
    assert any(says in str(w.message) for w in rec), [str(w.message) for w in rec]
    assert any(says in w and "\n" not in w for w in m.warnings), m.warnings
    with pytest.raises(robcal.CalibrationError) as e:
        job.calibrate(m, diagnose=False)
    message(e, "data.csv: the measured positions spread", "another unit")


@both
def test_millimetres_read_as_metres_is_an_error_naming_the_cell(tmp_path, via):
    """mirrors cli::input_errors::millimetres_read_as_metres_is_an_error_naming_the_cell"""
    setup = setup_file(tmp_path, units='angle = "deg"\nlength = "m"')
    data = data_csv(tmp_path)
    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data, via)
    message(e, "data.csv:2: column 'x': ", "is the column in millimetres?")


def test_metres_read_as_millimetres_warns(tmp_path):
    """mirrors cli::input_errors::metres_read_as_millimetres_warns_on_stderr"""
    setup = setup_file(tmp_path)

    def to_m(_, c):
        c[COL_X : COL_X + 3] = [repr(float(v) / 1000.0) for v in c[COL_X : COL_X + 3]]
        return c

    data = data_csv(tmp_path, to_m)
    job = robcal.Job.load(setup)
    with pytest.warns(robcal.RobcalWarning, match="are the positions in metres\\?") as rec:
        m = job.measurements(data)
    assert any("every x, y, z is within ±10" in str(w.message) for w in rec)
    assert any("every x, y, z is within ±10" in w for w in m.warnings), m.warnings
    with pytest.raises(robcal.CalibrationError) as e:
        job.calibrate(m, diagnose=False)
    message(e, "spread 0.001 times as far", "another unit")


@both
def test_unknown_joint_column_lists_the_chain_joints(tmp_path, via):
    """mirrors cli::input_errors::unknown_joint_column_lists_the_chain_joints"""
    setup = setup_file(tmp_path)
    data = data_csv(tmp_path)
    data.write_text(data.read_text().replace("a3", "A3", 1))
    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data, via)
    message(
        e,
        "data.csv:1: column 'A3': neither a fixed column nor a movable joint",
        "(joints: a1, a2, a3, a4, a5, a6)",
    )


@both
def test_unknown_marker_names_line_and_column(tmp_path, via):
    """mirrors cli::input_errors::unknown_marker_names_line_and_column"""
    setup = setup_file(tmp_path)

    def marker4(line, c):
        if line == 7:
            c[2] = "4"
        return c

    data = data_csv(tmp_path, marker4)
    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data, via)
    message(e, "data.csv:7: column 'marker': marker 4 is not declared in the setup")


@both
def test_unpaired_loaded_row_names_its_line(tmp_path, via):
    """mirrors cli::input_errors::unpaired_loaded_row_names_its_line"""
    setup = setup_file(tmp_path)
    data = data_csv(tmp_path, lambda line, c: c if line != 2 else None)
    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data, via)
    message(
        e,
        "data.csv:2: column 'load_kg': loaded row (config 1, rep 1, marker 1) has no unloaded row",
    )


@pytest.mark.parametrize("bad", ["nan", "inf", "-Infinity", "1e999"])
@both
def test_non_finite_value_names_line_and_column(tmp_path, bad, via):
    """mirrors cli::input_errors::non_finite_value_names_line_and_column
    (a DataFrame holds the float pandas read, so its cell text is numpy's)"""
    setup = setup_file(tmp_path)

    def put(line, c):
        if line == 5:
            c[COL_X + 1] = bad
        return c

    data = data_csv(tmp_path, put)
    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data, via)
    if via == "path":
        message(e, f"data.csv:5: column 'y': non-finite value '{bad}'")
    elif bad == "nan":
        # pandas' missing value: an empty cell (as a point's empty plane
        # cells in a frame of points and plane contacts).
        message(e, "data.csv:5: column 'y': empty cell")
    else:
        message(e, "data.csv:5: column 'y': non-finite value '")


def test_too_few_configurations_for_the_declared_model(tmp_path):
    """mirrors cli::input_errors::too_few_configurations_for_the_declared_model"""
    setup = setup_file(tmp_path)
    data = data_csv(tmp_path, lambda _, c: c if c[0] == "1" and c[2] == "1" else None)
    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data)
    message(
        e,
        "data.csv: too few configurations for the declared model: k_a5, k_a6 cannot be "
        "identified from 1 configuration(s)",
        "measure more configurations",
    )


def test_two_configurations_are_enough_for_the_paper_model(tmp_path):
    """mirrors cli::input_errors::two_configurations_are_enough_for_the_paper_model"""
    setup = setup_file(tmp_path)
    data = data_csv(tmp_path, lambda _, c: c if int(c[0]) <= 2 else None)
    result = calibrate(setup, data)
    assert result.failure is None
    assert result.converged
    assert json.loads(result.json())["converged"] is True


def test_a_compliance_without_loaded_rows_is_an_error_naming_it(tmp_path):
    """mirrors cli::input_errors::a_compliance_without_loaded_rows_is_an_error_naming_it"""
    setup = setup_file(tmp_path)
    data = data_csv(tmp_path, lambda _, c: c if c[COL_LOAD] == "0" else None)
    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data)
    message(e, "k_a6 declared, but no row puts a torque")


def test_a_load_centre_of_mass_on_a_joint_axis_is_an_error_naming_the_compliance(tmp_path):
    """mirrors cli::input_errors::a_load_centre_of_mass_on_a_joint_axis_is_an_error_naming_the_compliance"""
    setup = setup_file(tmp_path, replace=[("com = [0.25, 0.0, 0.30]", "com = [0.0, 0.0, 0.30]")])
    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data_csv(tmp_path))
    message(e, "k_a6 declared, but no row puts a torque")


def test_a_negative_compliance_beyond_three_sigma_is_an_error(tmp_path):
    """mirrors cli::input_errors::a_negative_compliance_beyond_three_sigma_is_an_error"""
    setup = setup_file(tmp_path, replace=[("com = [0.25, 0.0, 0.30]", "com = [-0.25, 0.0, 0.30]")])
    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data_csv(tmp_path))
    message(e, "k_a6 = -", "is negative by", "[load] com")


def test_one_joint_column_in_radians_is_an_error_naming_the_column(tmp_path):
    """mirrors cli::input_errors::one_joint_column_in_radians_is_an_error_naming_the_column"""
    setup = setup_file(tmp_path)

    def a3_rad(_, c):
        c[COL_A3] = repr(math.radians(float(c[COL_A3])))
        return c

    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data_csv(tmp_path, a3_rad))
    message(e, "column 'a3': its values fit rad far better")


def test_positions_in_centimetres_are_an_error(tmp_path):
    """mirrors cli::input_errors::positions_in_centimetres_are_an_error"""
    setup = setup_file(tmp_path)

    def to_cm(_, c):
        c[COL_X : COL_X + 3] = [repr(float(v) / 10.0) for v in c[COL_X : COL_X + 3]]
        return c

    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data_csv(tmp_path, to_cm))
    message(e, "spread 0.100 times as far", "another unit")


def test_validation_with_no_point_is_an_error(tmp_path):
    """mirrors cli::input_errors::validation_with_no_point_is_an_error"""
    setup = setup_file(tmp_path)
    data = data_csv(tmp_path)
    unloaded = data_csv(tmp_path, lambda _, c: c if c[COL_LOAD] == "0" else None, name="unloaded.csv")
    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data, validate=unloaded)
    message(e, "unloaded.csv: no point to validate on")


def test_validation_reports_points_mean_and_max(calibration, job):
    """mirrors cli::input_errors::validation_reports_points_mean_and_max"""
    result = job.calibrate(DATA, diagnose=False, validate=DATA)
    val = result.validation
    assert val["points"] == 270
    for m in ["1", "2", "3"]:
        mean, mx, rms = (val[f"per_marker_{k}_mm"][m] for k in ("mean", "max", "rms"))
        assert 0.0 < mean <= rms <= mx, (mean, rms, mx)
    assert calibration.validation is None


def test_a_fit_stopped_at_max_iter_says_so(job, calibration):
    """mirrors cli::input_errors::a_fit_stopped_at_max_iter_says_so
    (exit 1 is NotACalibrationError, the report kept in .result;
    --accept-unconverged is accept_unconverged=True)"""
    with pytest.raises(robcal.NotACalibrationError) as e:
        job.calibrate(DATA, diagnose=False, max_iter=1)
    message(e, "not a calibration", "did not converge")
    marked = e.value.result
    assert "did not converge" in marked.failure
    assert "did not converge" in marked.to_dict()["failure"]
    accepted = job.calibrate(DATA, diagnose=False, max_iter=1, accept_unconverged=True)
    assert accepted.json() == marked.json()
    assert accepted.converged is False
    assert any("did not converge" in w for w in accepted.warnings), accepted.warnings
    assert calibration.converged is True
    assert calibration.warnings == []
    assert calibration.failure is None
    assert "failure" not in calibration.to_dict()


@both
def test_absurd_numbers_name_the_value_and_where_in_the_data(tmp_path, via):
    """mirrors cli::input_errors::absurd_numbers_name_the_value_and_where (the data's)"""
    setup = setup_file(tmp_path)

    def load(line, c):
        if line == 3:
            c[COL_LOAD] = "1e308"
        return c

    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data_csv(tmp_path, load), via)
    message(e, "data.csv:3: column 'load_kg': load 1e308 kg is more than")

    def x(line, c):
        if line == 2:
            c[COL_X] = "1e300"
        return c

    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data_csv(tmp_path, x), via)
    message(e, "data.csv:2: column 'x': 1e297 m is more than")


ABSURD_SETUPS = [
    (
        "gravity = [0.0, 0.0, -9.80665]",
        "gravity = [0.0, 0.0, 0.0]",
        "setup.toml: load.gravity: [0.0, 0.0, 0.0] m/s² has norm 0",
    ),
    (
        "xyz = [0.0, 0.30, 0.20]",
        "xyz = [1e300, 0.30, 0.20]",
        "setup.toml: marker[0].xyz: [1e300, 0.3, 0.2] m is more than 100 m",
    ),
]


@pytest.mark.parametrize("edit", ABSURD_SETUPS, ids=["gravity", "marker"])
def test_absurd_numbers_name_the_value_and_where_in_the_setup(tmp_path, edit):
    """mirrors cli::input_errors::absurd_numbers_name_the_value_and_where (the setup's)"""
    a, b, says = edit
    setup = setup_file(tmp_path, replace=[(a, b)])
    with pytest.raises(robcal.InputError) as e:
        calibrate(setup, data_csv(tmp_path))
    message(e, says)
    # The same setup as text, named by setup_name.
    with pytest.raises(robcal.InputError) as e:
        robcal.Job.from_text(setup.read_text(), URDF.read_text(), setup_name="setup.toml")
    message(e, says)


def test_absurd_numbers_in_a_setup_dict_name_the_key():
    """mirrors cli::input_errors::absurd_numbers_name_the_value_and_where
    (a setup given as a dict: ``<setup>`` stands for the file)"""
    tomllib = pytest.importorskip("tomllib")
    urdf = URDF.read_text()
    d = tomllib.loads(SETUP.read_text())
    d["load"]["gravity"] = [0.0, 0.0, 0.0]
    with pytest.raises(robcal.InputError) as e:
        robcal.Job.from_text(d, urdf)
    message(e, "<setup>: load.gravity: [0.0, 0.0, 0.0] m/s² has norm 0")
    d = tomllib.loads(SETUP.read_text())
    d["marker"][0]["xyz"] = [1e300, 0.3, 0.2]
    with pytest.raises(robcal.InputError) as e:
        robcal.Job.from_text(d, urdf)
    message(e, "<setup>: marker[0].xyz: [1e300, 0.3, 0.2] m is more than 100 m")
    d = tomllib.loads(SETUP.read_text())
    d["load"]["com"] = [1j, 0, 0]
    with pytest.raises(TypeError) as e:
        robcal.Job.from_text(d, urdf)
    message(e, "setup load.com: a complex has no TOML form")


BAD_SETTINGS = [
    (dict(lambda_=-1.0), "lambda_ = -1: expected a finite number >= 0"),
    (dict(lambda_=float("nan")), "lambda_ = NaN: expected a finite number >= 0"),
    (dict(max_iter=0), "max_iter = 0: expected at least 1"),
    (dict(method="gauss"), "method \"gauss\": expected 'irls', 'wls' or 'ols'"),
    (dict(reregister=True), "reregister needs validate"),
]


@pytest.mark.parametrize(
    "settings,says", BAD_SETTINGS, ids=["lambda-negative", "lambda-nan", "max-iter-0", "method", "reregister"]
)
def test_a_bad_setting_is_a_value_error_naming_it(job, settings, says):
    """mirrors cli::input_errors::a_missing_or_bad_argument_is_a_usage_error_named_on_its_one_line
    (``--lambda -1``, ``--max-iter 0``; ``--method``, ``--reregister``
    without ``--validate``)"""
    with pytest.raises(ValueError) as e:
        job.calibrate(DATA, diagnose=False, **settings)
    message(e, says)


def test_a_missing_or_unknown_argument_is_a_type_error():
    """mirrors cli::input_errors::a_missing_or_bad_argument_is_a_usage_error_named_on_its_one_line
    ("not provided: --data <DATA>", and an argument clap does not know)"""
    with pytest.raises(TypeError) as e:
        robcal.calibrate(SETUP)  # type: ignore[call-arg]
    message(e, "data")
    with pytest.raises(TypeError) as e:
        robcal.calibrate(SETUP, DATA, lamda=1.0)
    message(e, "lamda")
    with pytest.raises(TypeError) as e:
        robcal.calibrate({"robot": "kr270.urdf"}, DATA)
    message(e, "setup: a dict or TOML text needs urdf=")
    with pytest.raises(TypeError) as e:
        robcal.Job.from_text(42, URDF.read_text())  # type: ignore[arg-type]
    message(e, "setup: expected a dict or TOML text")


@pytest.mark.parametrize("tolerance_um", [float("nan"), 0.0, -1.0, float("inf")])
def test_a_bad_tolerance_is_a_value_error(model, tolerance_um):
    """mirrors cli::input_errors::a_missing_or_bad_argument_is_a_usage_error_named_on_its_one_line
    (``compensate --tolerance-um nan``: "must be a finite number > 0")"""
    p = model.predict(Q1, 250.0, COM, marker=1)
    with pytest.raises(ValueError) as e:
        model.compensate(p, Q1, 250.0, COM, marker=1, tolerance_um=tolerance_um)
    message(e, "tolerance_um = ", "expected a finite number > 0")
    with pytest.raises(ValueError) as e:
        model.compensate(p, Q1, 250.0, COM, marker=1, max_iter=0)
    message(e, "max_iter = 0: expected at least 1")


def test_a_load_on_the_joint_axis_is_named_as_such_not_as_no_load(tmp_path):
    """mirrors cli::input_errors::a_load_on_the_joint_axis_is_named_as_such_not_as_no_load"""
    setup = setup_file(tmp_path, replace=[("com = [0.25, 0.0, 0.30]\n", "")])
    with pytest.raises(robcal.CalibrationError) as e:
        calibrate(setup, data_csv(tmp_path))
    message(
        e,
        "k_a6 declared, but no row puts a torque",
        "loaded rows, but their load acts through the joint's axis: check [load] com",
    )


def test_several_loads_against_one_unloaded_point_are_warned_about(tmp_path):
    """mirrors cli::input_errors::several_loads_against_one_unloaded_point_are_warned_about
    (the reader's warning, and the report's)"""
    setup = setup_file(tmp_path)
    out = []
    for i, line in enumerate(DATA.read_text().splitlines()):
        out.append(line)
        cells = line.split(",")
        if i > 0 and cells[COL_LOAD] != "0":
            cells[COL_LOAD] = str(float(cells[COL_LOAD]) / 2.0)
            out.append(",".join(cells))
    data = tmp_path / "data.csv"
    data.write_text("\n".join(out) + "\n")
    says = (
        "data.csv:2: 270 unloaded row(s) are each the reference of several loaded rows "
        "(first: line 2, for lines 3 and 4)"
    )
    with pytest.warns(robcal.RobcalWarning, match="sigma of the compliances are understated") as rec:
        result = calibrate(setup, data, method="ols")
    assert any(says in str(w.message) for w in rec), [str(w.message) for w in rec]
    assert any(says in w and "sigma of the compliances are understated" in w for w in result.warnings), result.warnings
    assert all("\n" not in w for w in result.warnings)


# --------------------------------------------------------------------------
# tests/cli/hostile.rs


def test_deep_urdf_nesting_is_an_error_not_an_abort(tmp_path):
    """mirrors cli::hostile::deep_urdf_nesting_is_an_error_not_an_abort"""
    deep = "<x>" * 15_000 + "</x>" * 15_000
    u = urdf_with(tmp_path, "deep.urdf", deep)
    with pytest.raises(robcal.InputError) as e:
        robcal.calibrate(setup_with_robot(tmp_path, u), DATA)
    msg = message(e, "deep.urdf:", "nested more than 64 deep")
    assert len(msg) < 400, len(msg)
    with pytest.raises(robcal.InputError) as e:
        robcal.Job.from_text(SETUP.read_text(), u.read_text(), urdf_name="deep.urdf")
    message(e, "deep.urdf:", "nested more than 64 deep")


def test_a_urdf_of_too_many_elements_is_refused(tmp_path):
    """mirrors cli::hostile::large_urdfs_are_refused_early_and_large_valid_ones_parse_in_linear_time
    (30,000 fixed links: more than 100000 XML elements)"""
    chain = "".join(
        f'<link name="e{i}"/><joint name="f{i}" type="fixed"><parent link="{"tool0" if i == 0 else f"e{i - 1}"}"/>'
        f'<child link="e{i}"/></joint>\n'
        for i in range(30_000)
    )
    u = urdf_with(tmp_path, "chain.urdf", chain)
    with pytest.raises(robcal.InputError) as e:
        robcal.calibrate(setup_with_robot(tmp_path, u), DATA)
    msg = message(e, "chain.urdf:", "more than 100000 XML elements")
    assert len(msg) < 400


def test_a_urdf_over_the_size_limit_is_refused_before_reading(tmp_path):
    """mirrors cli::hostile::large_urdfs_are_refused_early_and_large_valid_ones_parse_in_linear_time
    (a 17 MiB file: over the limit)"""
    big = tmp_path / "big.urdf"
    with open(big, "wb") as f:
        f.truncate(17 << 20)
    with pytest.raises(robcal.InputError) as e:
        robcal.Job.load(setup_with_robot(tmp_path, big))
    message(e, "big.urdf", "more than the limit")


def test_a_large_valid_urdf_calibrates(tmp_path):
    """mirrors cli::hostile::large_urdfs_are_refused_early_and_large_valid_ones_parse_in_linear_time
    (20,000 side links are a valid robot)"""
    side = "".join(
        f'<link name="s{i}"/><joint name="g{i}" type="fixed"><parent link="base_link"/>'
        f'<child link="s{i}"/></joint>\n'
        for i in range(20_000)
    )
    u = urdf_with(tmp_path, "side.urdf", side)
    result = robcal.calibrate(setup_with_robot(tmp_path, u), DATA, diagnose=False)
    assert result.failure is None


@pytest.mark.parametrize("kind", ["fifo", "device", "directory"])
@pytest.mark.parametrize("role", ["data", "validate", "setup", "robot", "model"])
def test_fifos_devices_and_directories_are_not_read(tmp_path, fifo, kind, role):
    """mirrors cli::hostile::fifos_devices_and_directories_are_not_read
    (``--data``, ``--validate``, ``--setup``, the setup's robot; and the
    model file of ``predict``/``compensate``: ``Model.load``)"""
    path = {"fifo": fifo, "device": Path("/dev/zero"), "directory": tmp_path}[kind]
    what = {"fifo": "a FIFO", "device": "a device", "directory": "a directory"}[kind]
    good = setup_with_robot(tmp_path, URDF)
    with pytest.raises(robcal.InputError) as e:
        if role == "data":
            robcal.calibrate(good, path)
        elif role == "validate":
            robcal.calibrate(good, DATA, validate=path, diagnose=False)
        elif role == "setup":
            robcal.Job.load(path)
        elif role == "robot":
            robcal.Job.load(setup_with_robot(tmp_path, path))
        else:
            robcal.Model.load(path)
    msg = message(e, str(path), what, "not a regular file")
    assert len(msg) < 400
    assert msg.startswith(str(path)), msg


def test_a_data_file_over_the_limit_is_refused_before_reading(job):
    """mirrors cli::hostile::a_data_file_over_the_limit_is_refused_before_reading
    (``--max-data-mib 0``)"""
    with pytest.raises(robcal.InputError) as e:
        job._native.read_measurements(str(DATA), 0)
    message(e, "measurements.csv", "more than the limit of 0 bytes")
    # The limit is the file's size: a limit of its size reads it.
    assert len(job._native.read_measurements(str(DATA), DATA.stat().st_size)) == 540


def _collide(tmp_path: Path, case: str):
    """An output directory holding an input of the calibration named like
    one of the files ``write`` writes; returns (result, dir, the input)."""
    out = tmp_path / "out"
    out.mkdir()
    if case == "data named model.json":
        shutil.copy(DATA, out / "model.json")
        result = robcal.Job.load(SETUP).calibrate(out / "model.json", diagnose=False)
        return result, out, out / "model.json"
    if case == "setup named robot.urdf":
        setup_file(out, name="robot.urdf")
        result = robcal.Job.load(out / "robot.urdf").calibrate(DATA, diagnose=False)
        return result, out, out / "robot.urdf"
    if case == "urdf named report.html":
        shutil.copy(URDF, out / "report.html")
        (tmp_path / "s.toml").write_text(
            SETUP.read_text().replace('robot = "kr270.urdf"', f"robot = {json.dumps(str(out / 'report.html'))}")
        )
        result = robcal.Job.load(tmp_path / "s.toml").calibrate(DATA, diagnose=False)
        return result, out, out / "report.html"
    if case == "validation data named model.json":
        shutil.copy(DATA, out / "model.json")
        result = robcal.Job.load(SETUP).calibrate(DATA, diagnose=False, validate=out / "model.json")
        return result, out, out / "model.json"
    raise AssertionError(case)


@pytest.mark.parametrize(
    "case",
    ["data named model.json", "setup named robot.urdf", "urdf named report.html", "validation data named model.json"],
)
def test_outputs_never_replace_inputs(tmp_path, case):
    """mirrors cli::hostile::outputs_never_replace_inputs_links_fifos_or_devices
    ("in.csv: cannot write: is an input of this command"): ``write(dir)``
    into the directory holding an input named like an output"""
    result, out, inp = _collide(tmp_path, case)
    before = inp.read_bytes()
    with pytest.raises(robcal.Error) as e:
        result.write(out)
    message(e, f"{inp}: is an input of this command", "cannot write", "refusing to overwrite")
    assert inp.read_bytes() == before
    assert listing(out) == [inp.name], "all or nothing, no temporary file left"


def test_outputs_never_replace_an_input_by_another_spelling(tmp_path, monkeypatch):
    """mirrors cli::hostile::outputs_never_replace_inputs_links_fifos_or_devices
    ("./in.csv: cannot write: is the input in.csv")"""
    (tmp_path / "sub").mkdir()
    shutil.copy(DATA, tmp_path / "model.json")
    before = (tmp_path / "model.json").read_bytes()
    monkeypatch.chdir(tmp_path)
    result = robcal.Job.load(SETUP).calibrate("model.json", diagnose=False)
    for d in [".", tmp_path / "sub" / "..", tmp_path]:
        with pytest.raises(robcal.Error) as e:
            result.write(d)
        message(e, "model.json: is the input model.json", "refusing to overwrite")
    assert (tmp_path / "model.json").read_bytes() == before
    assert listing(tmp_path) == ["model.json", "sub"]
    assert listing(tmp_path / "sub") == []


@pytest.mark.parametrize("kind", ["symlink", "fifo", "directory"])
def test_outputs_never_replace_links_fifos_or_directories(tmp_path, calibration, kind):
    """mirrors cli::hostile::outputs_never_replace_inputs_links_fifos_or_devices
    ("symbolic link", "refusing to replace")"""
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    if kind == "symlink":
        (out / "model.json").symlink_to(victim)
        says = ("model.json: is a symbolic link", "refusing to replace")
    elif kind == "fifo":
        os.mkfifo(out / "report.html")
        says = ("report.html: is not a regular file", "refusing to replace")
    else:
        (out / "robot.urdf").mkdir()
        says = ("robot.urdf: is not a regular file", "refusing to replace")
    before = listing(out)
    with pytest.raises(robcal.Error) as e:
        calibration.write(out)
    message(e, str(out), "cannot write", *says)
    assert listing(out) == before, "all or nothing, no temporary file left"
    assert victim.read_text() == "keep me"
    if kind == "symlink":
        assert (out / "model.json").is_symlink()
    if kind == "fifo":
        assert stat.S_ISFIFO(os.lstat(out / "report.html").st_mode)


def test_plots_are_all_or_nothing(tmp_path):
    """mirrors cli::hostile::plots_are_all_or_nothing (a directory named
    like the naive model's compensator figure in the way: nothing written)"""
    result = robcal.calibrate(KR / "setup-naive.toml", DATA)
    assert "01_compensator_a2.svg" in result.figures
    plots = tmp_path / "plots"
    (plots / "01_compensator_a2.svg").mkdir(parents=True)
    with pytest.raises(robcal.Error) as e:
        result.write(plots)
    message(e, "01_compensator_a2.svg", "refusing to replace")
    assert listing(plots) == ["01_compensator_a2.svg"]
    # And the written set is complete when nothing is in the way.
    result.write(tmp_path / "fresh")
    assert set(listing(tmp_path / "fresh")) == set(result.output_files())


def test_outputs_onto_an_input_file_are_refused(tmp_path):
    """mirrors cli::hostile::plots_are_all_or_nothing (``--plots`` onto an
    input file: exit 1, the input still a file)"""
    data = data_csv(tmp_path)
    before = data.read_bytes()
    result = robcal.calibrate(SETUP, data, diagnose=False)
    with pytest.raises(robcal.Error) as e:
        result.write(data)
    message(e, str(data))
    assert data.is_file() and data.read_bytes() == before
    assert listing(tmp_path) == ["data.csv"]


def test_outputs_onto_an_input_file_say_why(tmp_path):
    """mirrors cli::hostile::plots_are_all_or_nothing (the command's message
    for ``--output``/``--plots`` onto a file)"""
    data = data_csv(tmp_path)
    result = robcal.calibrate(SETUP, data, diagnose=False)
    with pytest.raises(robcal.Error) as e:
        result.write(data)
    message(e, f"{data}: exists and is not a directory")


def test_errors_quote_little_and_say_where(tmp_path, job):
    """mirrors cli::hostile::errors_quote_little_and_say_where"""
    lines = DATA.read_text().splitlines()
    cells = lines[1].split(",")
    cells[COL_X] = "7" * 1_000_000
    big = tmp_path / "cell.csv"
    big.write_text("\n".join([lines[0], ",".join(cells)] + lines[2:]) + "\n")
    with pytest.raises(robcal.InputError) as e:
        job.measurements(big)
    msg = message(e, "cell.csv:2: column 'x'")
    assert len(msg) < 300, len(msg)
    # Times beyond any clock: located, not a failure deep in a fit.
    t_lines = [lines[0] + ",t"] + [line + (",1.7e308" if i == 3 else ",0") for i, line in enumerate(lines) if i > 0]
    t = tmp_path / "t.csv"
    t.write_text("\n".join(t_lines) + "\n")
    with pytest.raises(robcal.InputError) as e:
        robcal.calibrate(SETUP, t)
    message(e, "t.csv:4: column 't'", "from 0")


def test_a_table_quotes_little_and_says_where(job):
    """mirrors cli::hostile::errors_quote_little_and_say_where (a column of
    text cells given as a mapping)"""
    pd = pytest.importorskip("pandas")
    df = pd.read_csv(DATA)
    cols = {c: df[c].to_numpy() for c in df.columns}
    x = cols["x"].astype(object)
    x[0] = "7" * 1_000_000
    cols["x"] = x
    with pytest.raises(robcal.InputError) as e:
        job.measurements(cols, name="cell.csv")
    msg = message(e, "cell.csv:2: column 'x'")
    assert len(msg) < 300, len(msg)


# --------------------------------------------------------------------------
# tests/cli/apply.rs: predict, compensate and the model file


def test_compensate_refuses_targets_of_the_wrong_width(model):
    """mirrors cli::apply::compensated_commands_put_the_markers_on_their_targets
    ("bad.csv:1: column 'x_mm'": a target that is not x, y, z in m)"""
    with pytest.raises(ValueError) as e:
        model.compensate(np.zeros((3, 2)), Q3, LOADS3, COM, marker=1)
    message(e, "targets_m: shape (3, 2): expected (3,) or (n, 3) points")


@pytest.mark.parametrize(
    "load, says",
    [
        (-1.0, "load_kg: value 0 is -1: a mass is >= 0"),
        (1e7, "load_kg: value 0 is 1e7: expected a finite value within ±100000 kg"),
    ],
    ids=["negative", "1e7"],
)
def test_compensate_refuses_an_impossible_load(model, load, says):
    """mirrors cli::apply::compensated_commands_put_the_markers_on_their_targets
    ("column 'load_kg': negative mass", "1e7 kg is beyond 1e5 kg")"""
    p = model.predict(Q1, 250.0, COM, marker=1)
    with pytest.raises(ValueError) as e:
        model.compensate(p + 0.005, Q1, load, COM, marker=1)
    message(e, says)
    with pytest.raises(ValueError) as e:
        model.predict(Q1, load, COM, marker=1)
    message(e, says)


def test_compensate_refuses_a_centre_of_mass_beyond_any_robot(model):
    """mirrors cli::apply::compensated_commands_put_the_markers_on_their_targets
    ("column 'com_z_m': -2e4 m is beyond 1e4 m in magnitude")"""
    p = model.predict(Q1, 250.0, COM, marker=1)
    with pytest.raises(ValueError) as e:
        model.compensate(p, Q1, 250.0, [0.25, 0.0, -2e4], marker=1)
    message(e, "com_m: value 2 is -20000: expected a finite value within ±10000 m")


def test_compensate_refuses_a_joint_beyond_any_robot(model):
    """mirrors cli::apply::compensated_commands_put_the_markers_on_their_targets
    ("column 'a2_rad': 1e300 rad is beyond 1e4 rad in magnitude")"""
    p = model.predict(Q1, 250.0, COM, marker=1)
    q = Q1.copy()
    q[1] = 1e300
    with pytest.raises(ValueError) as e:
        model.compensate(p, q, 250.0, COM, marker=1)
    message(e, "q_start column 1: value 0 is ", "expected a finite value within ±10000 rad")


def test_a_joint_beyond_any_robot_is_quoted_short(model):
    """mirrors cli::apply::compensated_commands_put_the_markers_on_their_targets
    and cli::hostile::errors_quote_little_and_say_where (1e300 rad, said short)"""
    q = Q1.copy()
    q[1] = 1e300
    with pytest.raises(ValueError) as e:
        model.predict(q, 250.0, COM, marker=1)
    msg = message(e, "q column 1", "1e300")
    assert len(msg) < 300, len(msg)


def test_a_target_out_of_reach_is_a_calibration_error(model):
    """mirrors cli::apply::compensated_commands_put_the_markers_on_their_targets
    ("bad.csv:2: cannot reach the target": a target 10 m away)"""
    p = model.predict(Q1, 250.0, COM, marker=1)
    p[0] = 10.0
    with pytest.raises(robcal.CalibrationError) as e:
        model.compensate(p, Q1, 250.0, COM, marker=1)
    message(e, "row 0: cannot reach the target")


def test_a_report_json_is_not_a_model_file(tmp_path):
    """mirrors cli::apply::compensated_commands_put_the_markers_on_their_targets
    (a report JSON: "no 'predictor' section")"""
    report = tmp_path / "report.json"
    report.write_text('{"rms_um": 1}')
    with pytest.raises(robcal.InputError) as e:
        robcal.Model.load(report)
    message(e, f"{report}: no 'predictor' section")
    with pytest.raises(robcal.InputError) as e:
        robcal.Model.from_json(report.read_text())
    message(e, "no 'predictor' section")
    for text, says in [("not json {", "not JSON"), ("", "not JSON")]:
        with pytest.raises(robcal.InputError) as e:
            robcal.Model.from_json(text)
        message(e, says)
    with pytest.raises(robcal.InputError) as e:
        robcal.Model.load(tmp_path / "missing.json")
    message(e, "missing.json: cannot read the model file")


def _first_joint_law(compact: str) -> str:
    i = compact.index('"joint_law":[') + len('"joint_law":[')
    depth = 0
    for k, ch in enumerate(compact[i:]):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
            if depth == 0:
                return compact[i : i + k + 1]
    raise AssertionError("no joint_law record")


EDITS = ["unit", "misspelt", "twice"]


@pytest.mark.parametrize("edit", EDITS)
def test_a_model_file_edited_out_of_its_format_is_refused(tmp_path, model_json, edit):
    """mirrors cli::apply::a_model_file_edited_out_of_its_format_is_refused"""
    compact = "".join(model_json.split())
    law = '"units":{"backlash":"rad","compliance":"rad/(N*m)"'
    assert law in compact, "the writer's units moved"
    robcal.Model.from_json(compact)  # the file as written reads
    first = _first_joint_law(compact)
    edited, says = {
        "unit": (
            compact.replace(law, law.replace('"rad/(N*m)"', '"urad/(N*m)"'), 1),
            "joint_law of 'a2': unit of compliance 'urad/(N*m)', where robcal writes and reads 'rad/(N*m)'",
        ),
        "misspelt": (
            compact.replace('"compliance":0.0,"compliance_table"', '"complianse":0.0,"compliance_table"', 1),
            "unknown field `complianse`",
        ),
        "twice": (
            compact.replace(first, f"{first},{first}", 1),
            "joint_law of 'a2': listed twice",
        ),
    }[edit]
    assert edited != compact, f"{says}: the edit did not apply"
    bad = tmp_path / "edited.json"
    bad.write_text(edited)
    with pytest.raises(robcal.InputError) as e:
        robcal.Model.load(bad)
    message(e, f"{bad}: ", says)
    with pytest.raises(robcal.InputError) as e:
        robcal.Model.from_json(edited)
    message(e, says)


def test_a_payload_far_beyond_the_calibrations_is_predicted_with_a_warning(model, model_json):
    """mirrors cli::apply::a_payload_far_beyond_the_calibrations_is_predicted_with_a_warning
    (the row is numbered from 0, not the file's line)"""
    assert '"heaviest_payload_kg": 275.8' in model_json, "the paper's load"
    with warnings.catch_warnings():
        warnings.simplefilter("error", robcal.RobcalWarning)
        p = model.predict(Q3, [0.0, 250.0, 551.0], COM, marker=1)
    assert p.shape == (3, 3) and np.isfinite(p).all()
    with pytest.warns(robcal.RobcalWarning) as rec:
        p = model.predict(Q3, [250.0, 25000.0, 600.0], COM, marker=1)
    said = [str(w.message) for w in rec if issubclass(w.category, robcal.RobcalWarning)]
    assert len(said) == 1, said
    assert "\n" not in said[0]
    assert (
        "2 of 3 rows carry a payload more than 2 times the heaviest of the calibration "
        "(275.8 kg), up to 25000 kg (row 1)" in said[0]
    ), said[0]
    assert p.shape == (3, 3) and np.isfinite(p).all()
    # compensate says it too.
    with pytest.warns(robcal.RobcalWarning, match="up to 25000 kg \\(row 1\\)"):
        model.compensate(p, Q3, [250.0, 25000.0, 600.0], COM, marker=1)
    # A file written before the key: read, nothing to compare with.
    key = model_json.index(',\n    "heaviest_payload_kg"')
    end = key + 2 + model_json[key + 2 :].index("\n")
    old = robcal.Model.from_json(model_json[:key] + model_json[end:])
    with warnings.catch_warnings():
        warnings.simplefilter("error", robcal.RobcalWarning)
        old.predict(Q1, 25000.0, COM, marker=1)
    bad = model_json.replace('"heaviest_payload_kg": 275.8', '"heaviest_payload_kg": -1')
    with pytest.raises(robcal.InputError) as e:
        robcal.Model.from_json(bad)
    message(e, "heaviest_payload_kg: -1 kg is not a payload")


# --------------------------------------------------------------------------
# numpy: Model.predict and Model.compensate


@pytest.mark.parametrize(
    "q",
    [Q1[:5], np.tile(Q1, (2, 2)), Q3[:0], Q3[None], np.float64(1.0), np.array([])],
    ids=["5", "2x12", "0x6", "1x3x6", "scalar", "empty"],
)
def test_predict_refuses_joint_values_of_the_wrong_shape(model, q):
    """numpy: q is (dof,) or (n, dof), n >= 1"""
    with pytest.raises(ValueError) as e:
        model.predict(q, marker=1)
    message(e, "q: ")


def test_predict_refuses_ragged_joint_values_naming_them(model):
    """numpy: rows of different lengths"""
    with pytest.raises(ValueError) as e:
        model.predict([[1.0] * 6, [1.0] * 5], marker=1)
    message(e, "q")
    assert str(e.value).startswith("q"), str(e.value)


@pytest.mark.parametrize(
    "q, dtype",
    [
        (Q1.astype(str), "<U"),
        (Q1.astype(complex), "complex128"),
        (Q1.astype(object), "object"),
        (Q1 > 0, "bool"),
        ([str(v) for v in Q1], "<U"),
    ],
    ids=["str", "complex", "object", "bool", "list-of-str"],
)
def test_predict_refuses_joint_values_that_are_not_real(model, q, dtype):
    """numpy: strings, complex numbers, objects are a TypeError"""
    with pytest.raises(TypeError) as e:
        model.predict(q, marker=1)
    message(e, "q: expected real numbers, got an array of dtype", dtype)


def test_predict_takes_integers_and_float32(model):
    """numpy: integer and float32 joint values are real numbers"""
    p = model.predict(Q1.astype(np.float32), 0.0, COM, marker=1)
    assert p.shape == (3,) and np.isfinite(p).all()
    p = model.predict(np.zeros(6, dtype=np.int32), 0.0, COM, marker=1)
    assert p.shape == (3,) and np.isfinite(p).all()


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 1e5])
def test_predict_refuses_non_finite_joint_values_naming_the_cell(model, bad):
    """numpy: mirrors cli::input_errors::non_finite_value_names_line_and_column
    for an array (the column and row of the value)"""
    q = Q3.copy()
    q[2, 4] = bad
    with pytest.raises(ValueError) as e:
        model.predict(q, LOADS3, COM, marker=1)
    message(e, "q column 4: value 2 is ", "expected a finite value within ±10000 rad")


@pytest.mark.parametrize(
    "load, says",
    [
        (-1.0, "load_kg: value 0 is -1: a mass is >= 0"),
        (1e7, "load_kg: value 0 is 1e7: expected a finite value within ±100000 kg"),
        (np.nan, "load_kg: value 0 is NaN: expected a finite value"),
        (np.inf, "load_kg: value 0 is inf: expected a finite value"),
    ],
    ids=["negative", "huge", "nan", "inf"],
)
def test_predict_refuses_an_impossible_load(model, load, says):
    """numpy: negative, huge and non-finite load_kg"""
    with pytest.raises(ValueError) as e:
        model.predict(Q1, load, COM, marker=1)
    message(e, says)
    with pytest.raises(ValueError) as e:
        model.predict(Q3, [250.0, 250.0, load], COM, marker=1)
    message(e, says.replace("value 0", "value 2"))


@pytest.mark.parametrize(
    "load, com, says",
    [
        ([1.0, 2.0], COM, "load_kg: shape (2,): expected () or (3,)"),
        ([[1.0, 2.0, 3.0]], COM, "load_kg: shape (1, 3): expected () or (3,)"),
        (LOADS3, [0.0, 0.0], "com_m: shape (2,): expected (3,) or (3, 3)"),
        (LOADS3, np.zeros((2, 3)), "com_m: shape (2, 3): expected (3,) or (3, 3)"),
        (LOADS3, [np.nan, 0.0, 0.0], "com_m: value 0 is NaN"),
        ("5", COM, "load_kg: expected real numbers"),
        (1 + 2j, COM, "load_kg: expected real numbers"),
        (LOADS3, ["a", "b", "c"], "com_m: expected real numbers"),
    ],
    ids=["load-2-of-3", "load-1x3", "com-2", "com-2x3", "com-nan", "load-str", "load-complex", "com-str"],
)
def test_predict_refuses_payloads_that_do_not_match_the_rows(model, load, com, says):
    """numpy: one load and centre of mass for all rows, or one per row"""
    with pytest.raises((ValueError, TypeError)) as e:
        model.predict(Q3, load, com, marker=1)
    message(e, says)
    expected = TypeError if "expected real numbers" in says else ValueError
    assert isinstance(e.value, expected), type(e.value)


def test_predict_needs_a_marker_the_model_has(model):
    """numpy: which marker, when the model has three"""
    with pytest.raises(robcal.CalibrationError) as e:
        model.predict(Q1)
    message(e, "which marker? the model has markers [1, 2, 3]")
    with pytest.raises(robcal.CalibrationError) as e:
        model.predict(Q1, marker=9)
    message(e, "no marker 9 in the calibration (markers [1, 2, 3])")
    with pytest.raises(TypeError):
        model.predict(Q1, marker="1")


@pytest.mark.parametrize("call", ["predict", "predict-default", "compensate"])
def test_one_load_is_taken_for_every_row(model, call):
    """numpy: a scalar load_kg (as documented: "one, or one per row"); once
    refused for n > 1 rows ('load_kg: shape (1,)': np.ascontiguousarray
    made the 0-d array (1,))"""
    if call == "predict":
        p = model.predict(Q3, 250.0, COM, marker=1)
        assert np.allclose(p, model.predict(Q3, LOADS3, COM, marker=1))
    elif call == "predict-default":
        p = model.predict(Q3, marker=1)
        assert np.allclose(p, model.predict(Q3, [0.0] * 3, COM, marker=1))
    else:
        t = model.predict(Q3, LOADS3, COM, marker=1)
        c = model.compensate(t, Q3, 250.0, COM, marker=1)
        assert c.q.shape == (3, 6)


def test_a_nan_in_joint_values_of_several_rows_is_named_with_the_default_load(model):
    """numpy: mirrors cli::input_errors::non_finite_value_names_line_and_column
    (the NaN named, not the default load_kg)"""
    q = Q3.copy()
    q[2, 4] = np.nan
    with pytest.raises(ValueError) as e:
        model.predict(q, marker=1)
    message(e, "q column 4: value 2 is NaN")


@pytest.mark.parametrize("call", ["calibrate-max_iter", "compensate-max_iter", "predict-marker"])
def test_a_negative_count_is_a_value_error_naming_it(job, model, call):
    """mirrors cli::input_errors::a_missing_or_bad_argument_is_a_usage_error_named_on_its_one_line
    ("--max-iter: must be a whole number from 1 to"), for -1"""
    with pytest.raises(ValueError) as e:
        if call == "calibrate-max_iter":
            job.calibrate(DATA, diagnose=False, max_iter=-1)
        elif call == "compensate-max_iter":
            model.compensate(model.predict(Q1, marker=1), Q1, marker=1, max_iter=-1)
        else:
            model.predict(Q1, marker=-1)
    message(e, call.split("-")[1])


def test_compensate_refuses_rows_that_do_not_match(model):
    """numpy: as many targets (and rotations) as rows of q_start"""
    t = model.predict(Q3, LOADS3, COM, marker=1)
    with pytest.raises(ValueError) as e:
        model.compensate(t[:2], Q3, LOADS3, COM, marker=1)
    message(e, "targets_m: 2 targets for 3 rows of q_start")
    with pytest.raises(ValueError) as e:
        model.compensate(t, Q3[:2], [250.0, 250.0], COM, marker=1)
    message(e, "targets_m: 3 targets for 2 rows of q_start")
    with pytest.raises(ValueError) as e:
        model.compensate(t, Q3, LOADS3, COM, marker=1, rotation_rad=np.zeros((2, 3)))
    message(e, "rotation_rad: 2 rotations for 3 rows of q_start")
    with pytest.raises(ValueError) as e:
        model.compensate(t, Q3, [1.0, 2.0], COM, marker=1)
    message(e, "load_kg: shape (2,): expected () or (3,)")
    with pytest.raises(ValueError) as e:
        model.compensate(t[:0], Q3[:0], LOADS3, COM, marker=1)
    message(e, "q_start: shape (0, 6)")


@pytest.mark.parametrize(
    "what, bad, says",
    [
        ("targets", np.nan, "targets_m: value 4 is NaN: expected a finite value within ±10000 m"),
        ("targets", 1e5, "targets_m: value 4 is 100000: expected a finite value within ±10000 m"),
        ("rotation", np.nan, "rotation_rad: value 0 is NaN: expected a finite value within ±10000 rad"),
        ("rotation", np.inf, "rotation_rad: value 0 is inf"),
        ("q_start", np.nan, "q_start column 3: value 1 is NaN"),
    ],
)
def test_compensate_refuses_non_finite_values(model, what, bad, says):
    """numpy: NaN, inf and values beyond any robot in each argument"""
    t = model.predict(Q3, LOADS3, COM, marker=1)
    q = Q3.copy()
    rot = None
    if what == "targets":
        t[1, 1] = bad
    elif what == "rotation":
        rot = np.full((3, 3), bad)
    else:
        q[1, 3] = bad
    with pytest.raises(ValueError) as e:
        model.compensate(t, q, LOADS3, COM, marker=1, rotation_rad=rot)
    message(e, says)


@pytest.mark.parametrize("dtype", [str, complex, object])
def test_compensate_refuses_targets_that_are_not_real(model, dtype):
    """numpy: strings, complex numbers, objects are a TypeError"""
    t = model.predict(Q3, LOADS3, COM, marker=1)
    with pytest.raises(TypeError) as e:
        model.compensate(t.astype(dtype), Q3, LOADS3, COM, marker=1)
    message(e, "targets_m: expected real numbers")
    with pytest.raises(TypeError) as e:
        model.compensate(t, Q3.astype(dtype), LOADS3, COM, marker=1)
    message(e, "q_start: expected real numbers")


# --------------------------------------------------------------------------
# Tables: Job.measurements(dict | DataFrame)


@pytest.fixture(scope="module")
def columns() -> dict:
    pd = pytest.importorskip("pandas")
    df = pd.read_csv(DATA)
    return {c: df[c].to_numpy() for c in df.columns}


def test_a_dataframe_with_a_nan_cell_names_line_and_column(job, tmp_path):
    """mirrors cli::input_errors::non_finite_value_names_line_and_column:
    a NaN cell of a DataFrame is pandas' missing value, an empty cell: the
    CSV reader's error, line and column"""
    pd = pytest.importorskip("pandas")
    df = pd.read_csv(DATA)
    df.loc[3, "y"] = np.nan
    with pytest.raises(robcal.InputError) as e:
        job.measurements(df)
    message(e, "<DataFrame>:5: column 'y': empty cell")
    with pytest.raises(robcal.InputError) as e:
        job.calibrate(df, diagnose=False)
    message(e, "<DataFrame>:5: column 'y': empty cell")
    # The same cell in a file (pandas writes NaN as an empty cell): the same error.
    path = tmp_path / "frame.csv"
    df.to_csv(path, index=False)
    with pytest.raises(robcal.InputError) as e:
        job.measurements(path)
    message(e, "frame.csv:5: column 'y': empty cell")
    # A missing marker (a float column with NaN) is named too.
    df = pd.read_csv(DATA)
    df["marker"] = df["marker"].astype(float)
    df.loc[0, "marker"] = np.nan
    with pytest.raises(robcal.InputError) as e:
        job.measurements(df, name="lab.csv")
    message(e, "lab.csv:2: column 'marker': empty cell")
    # A nullable integer column's missing value.
    df = pd.read_csv(DATA)
    df["config"] = df["config"].astype("Int64")
    df.loc[2, "config"] = pd.NA
    with pytest.raises(robcal.InputError) as e:
        job.measurements(df)
    message(e, "<DataFrame>:4: column 'config'")


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_mapping_with_a_non_finite_value_names_line_and_column(job, columns, bad):
    """mirrors cli::input_errors::non_finite_value_names_line_and_column (a mapping of columns)"""
    cols = dict(columns)
    y = cols["y"].copy()
    y[3] = bad
    cols["y"] = y
    with pytest.raises(robcal.InputError) as e:
        job.measurements(cols)
    if np.isnan(bad):
        message(e, "<table>:5: column 'y': empty cell")
    else:
        message(e, "<table>:5: column 'y': non-finite value '")


def test_a_mapping_reads(job, columns):
    """numpy: the shipped table as a mapping reads like the file"""
    assert len(job.measurements(columns)) == len(job.measurements(DATA)) == 540
    cols = dict(columns)
    cols["x"] = cols["x"].astype(np.float32)
    assert len(job.measurements(cols)) == 540
    cols["x"] = columns["x"].astype(str)
    assert len(job.measurements(cols)) == 540


@pytest.mark.parametrize(
    "column, says",
    [
        (lambda x: x.reshape(-1, 1), "column 'x': shape (540, 1): expected one value per row"),
        (lambda x: x.reshape(-1, 2), "column 'x': shape (270, 2): expected one value per row"),
        (lambda x: np.float64(3.0), "column 'x': shape (): expected one value per row"),
        (lambda x: x[:-1], "column 'x' has 539 values, column 'config' 540"),
    ],
    ids=["540x1", "270x2", "scalar", "539"],
)
def test_a_mapping_of_the_wrong_shape_is_a_value_error(job, columns, column, says):
    """numpy: one value per row in every column"""
    cols = dict(columns)
    cols["x"] = column(cols["x"])
    with pytest.raises(ValueError) as e:
        job.measurements(cols)
    message(e, says)


@pytest.mark.parametrize(
    "make, says",
    [
        (lambda x: x.astype(complex), "<table>:2: column 'x': '(732.1436303347281+0j)' is not a number"),
        (lambda x: _put(x.astype(object), 4, None), "<table>:6: column 'x': 'None' is not a number"),
        (lambda x: _put(x.astype(object), 4, "abc"), "<table>:6: column 'x': 'abc' is not a number"),
        (lambda x: x > 1000, "<table>:2: column 'x': 'False' is not a number"),
    ],
    ids=["complex", "object-None", "object-str", "bool"],
)
def test_a_mapping_column_that_is_not_numbers_names_the_cell(job, columns, make, says):
    """numpy: complex, object and bool columns are read as text cells,
    so the reader refuses the first one that is not a number, by line and
    column (an InputError, as the file's)"""
    cols = dict(columns)
    cols["x"] = make(cols["x"])
    with pytest.raises(robcal.InputError) as e:
        job.measurements(cols)
    message(e, says)


def _put(a: np.ndarray, i: int, v) -> np.ndarray:
    a = a.copy()
    a[i] = v
    return a


def test_an_empty_table_is_an_input_error(job, columns):
    """numpy: empty arrays, and no columns at all"""
    with pytest.raises(robcal.InputError) as e:
        job.measurements({k: v[:0] for k, v in columns.items()})
    message(e, "<table>:1: no measurement rows")
    with pytest.raises(robcal.InputError) as e:
        job.measurements({})
    message(e, "<table>:1: no header row")
    pd = pytest.importorskip("pandas")
    with pytest.raises(robcal.InputError) as e:
        job.measurements(pd.read_csv(DATA).iloc[:0])
    message(e, "<DataFrame>:1: no measurement rows")


def test_a_negative_load_in_a_table_names_the_cell(job, columns):
    """numpy: mirrors cli::apply's "column 'load_kg': negative mass" for a table"""
    cols = dict(columns)
    cols["load_kg"] = -cols["load_kg"]
    with pytest.raises(robcal.InputError) as e:
        job.measurements(cols)
    message(e, "<table>:3: column 'load_kg': negative load -255.8 kg")


def test_data_that_is_not_a_table_is_a_type_error(job):
    """numpy: a path, a DataFrame or a mapping"""
    for data, name in [(42, "int"), ([1, 2, 3], "list"), (np.zeros((3, 13)), "ndarray")]:
        with pytest.raises(TypeError) as e:
            job.measurements(data)
        message(e, "data: expected a path, a pandas DataFrame or a mapping of columns", f"got {name}")


def test_a_datetime_column_is_refused(job, columns):
    """numpy: a datetime64 column is not a number of the contract's units"""
    cols = dict(columns)
    cols["x"] = cols["x"].astype("datetime64[ns]")
    with pytest.raises((TypeError, ValueError, robcal.InputError)) as e:
        job.measurements(cols)
    message(e, "x")


@pytest.mark.parametrize("via", ["mapping", "csv"])
def test_a_cell_with_a_line_end_is_still_a_one_line_error(job, columns, tmp_path, via):
    """mirrors cli::hostile::errors_quote_little_and_say_where (one line
    whatever the cell holds)"""
    if via == "mapping":
        cols = dict(columns)
        cols["marker"] = _put(cols["marker"].astype(str).astype(object), 3, "1\n2")
        with pytest.raises(robcal.InputError) as e:
            job.measurements(cols)
        message(e, "<table>:5: column 'marker': '1", "is not a marker id")
    else:
        lines = DATA.read_text().splitlines()
        cells = lines[4].split(",")
        cells[2] = '"1\n2"'
        lines[4] = ",".join(cells)
        p = tmp_path / "nl.csv"
        p.write_text("\n".join(lines) + "\n")
        with pytest.raises(robcal.InputError) as e:
            job.measurements(p)
        message(e, "nl.csv:5: column 'marker': '1", "is not a marker id")


# --------------------------------------------------------------------------
# robcal.plan (mirrors cli::plan::what_cannot_be_planned_is_one_line_and_nothing_written)


@pytest.mark.parametrize(
    "kwargs, error, expect",
    [
        ({"poses": 5}, robcal.CalibrationError, "--load-kg"),
        ({"poses": 50, "candidates": 20, "load_kg": [250.0]}, robcal.CalibrationError,
         "50 poses to choose from 20 candidates"),
        ({"poses": 5, "load_kg": [250.0], "limits": {"a9": (0.0, 1.0)}}, robcal.CalibrationError,
         "unknown joint 'a9'"),
        ({"poses": 5, "load_kg": [250.0], "limits": {"a2": (-9.0, 9.0)}}, robcal.CalibrationError,
         "a2=-9:9"),
        ({"poses": 5, "load_kg": [-3.0]}, ValueError, "a mass from 0"),
        ({"poses": 5, "candidates": 100001}, ValueError, "100001"),
        ({"poses": 0, "load_kg": [250.0]}, ValueError, "poses = 0"),
        ({"poses": 5, "load_kg": [250.0], "criterion": "x"}, ValueError, 'criterion "x"'),
        ({"poses": 5, "load_kg": [250.0], "exchange_passes": -1}, ValueError, "exchange_passes = -1"),
        ({"poses": 5, "load_kg": [float("nan")]}, ValueError, "a mass from 0"),
    ],
)
def test_what_cannot_be_planned_is_one_line(kwargs, error, expect):
    """mirrors cli::plan::what_cannot_be_planned_is_one_line_and_nothing_written"""
    with pytest.raises(error) as e:
        robcal.plan(SETUP, **kwargs)
    message(e, expect)


def test_a_pool_that_is_not_one_names_the_value():
    """mirrors cli::plan::what_cannot_be_planned_is_one_line_and_nothing_written
    (the pool with a NaN)"""
    with pytest.raises(ValueError) as e:
        robcal.plan(SETUP, 1, pool=[[0, 0, 0, 0, float("nan"), 0]])
    message(e, "pool_q: value 4 is NaN")
    with pytest.raises(ValueError) as e:
        robcal.plan(SETUP, 1, pool=[[0, 0, 0, 0, 0]])
    message(e, "pool: shape (1, 5)")


# --------------------------------------------------------------------------
# Found by a second reading


def test_joint_values_in_a_frame_are_taken_by_name(model):
    """A DataFrame's joint columns by name and unit, never by position."""
    cols = [f"a{i}_rad" for i in range(1, 7)]
    q = pd.DataFrame([Q1], columns=cols)
    want = model.predict(Q1, marker=1)
    assert np.array_equal(model.predict(q[cols[::-1]], marker=1)[0], want)
    with pytest.raises(ValueError) as e:
        model.predict(pd.DataFrame([np.rad2deg(Q1)], columns=[c[:-4] for c in cols]), marker=1)
    message(e, "q: no column 'a1_rad'")


def test_a_string_or_a_bool_is_not_a_number():
    with pytest.raises(TypeError) as e:
        robcal.plan(SETUP, 4, load_kg="250")
    message(e, "load_kg: expected real numbers")
    with pytest.raises(TypeError) as e:
        robcal.calibrate(SETUP, DATA, max_iter=True)
    message(e, "max_iter: expected a whole number")


def test_a_pool_file_is_the_commands_pool_and_excludes_candidates(repo):
    by_file = robcal.plan(SETUP, 6, pool=repo / "data/kr270/poses.csv")
    by_frame = robcal.plan(SETUP, 6, pool=pd.read_csv(repo / "data/kr270/poses.csv"))
    assert by_file.csv() == by_frame.csv()
    with pytest.raises(ValueError) as e:
        robcal.plan(SETUP, 6, pool=repo / "data/kr270/poses.csv", candidates=100)
    message(e, "candidates: random candidates are drawn without a pool")
    # Rows of joint values carry their payload by load_kg.
    rows = pd.read_csv(repo / "data/kr270/poses.csv")[[f"a{i}_rad" for i in range(1, 7)]].to_numpy()
    assert robcal.plan(SETUP, 3, pool=rows, load_kg=250.0).load_kg.tolist() == [250.0] * 3


def test_a_table_without_columns_is_refused(job):
    with pytest.raises(ValueError) as e:
        job._native.table_measurements([], 2**40)
    message(e, "a measurement table needs its columns")


def test_a_setup_dict_with_control_characters_means_what_it_says(repo):
    """TOML escapes, numpy booleans and 0-d arrays in a setup dict."""
    urdf = (repo / "data/kr270/kr270.urdf").read_text()
    import tomllib

    setup = tomllib.loads((repo / "data/kr270/setup.toml").read_text())
    setup["model"]["base_frame"] = np.bool_(False)
    setup["noise"]["lambda"] = np.array(1.0)
    job = robcal.Job.from_text(setup, urdf)
    assert "base_frame = false" in job.setup_toml()
    setup["base_link"] = 'base_link\r"\\'
    with pytest.raises(robcal.InputError) as e:
        robcal.Job.from_text(setup, urdf)
    message(e, "base_link")


def test_huge_limits_are_said_short():
    with pytest.raises(ValueError) as e:
        robcal.plan(SETUP, 4, load_kg=[250.0], limits={"a1": (-1e300, 1e300)})
    message(e, "-1e300")
    assert len(str(e.value)) < 200


def test_six_d_exports_import_with_their_convention(tmp_path):
    """mirrors host-tests poses::hostile_six_d_exports: Euler angles need
    their convention; gimbal lock is a warning; a quaternion off unit norm
    is an error naming line and column"""
    euler = tmp_path / "euler.csv"
    euler.write_text(
        "j1_rad,x1_m,y1_m,z1_m,rx1_deg,ry1_deg,rz1_deg\n"
        "0.1,1,2,3,10,20,30\n0.2,1,2,3,10,89.99,30\n"
    )
    out = tmp_path / "out.csv"
    with pytest.raises(robcal.InputError) as e:
        robcal.import_poses(euler, out)
    message(e, "--euler")
    with pytest.raises(ValueError) as e:
        robcal.import_poses(euler, out, euler="xyz")
    message(e, "fixed-xyz")
    with pytest.warns(robcal.RobcalWarning, match="gimbal lock"):
        assert robcal.import_poses(euler, out, euler="fixed-xyz") == (2, 2)
    assert out.read_text().splitlines()[0].endswith(",x,y,z,rx,ry,rz")
    quat = tmp_path / "quat.csv"
    quat.write_text("j1_rad,x1_m,y1_m,z1_m,qw1,qx1,qy1,qz1\n0.1,1,2,3,0.9,0.1,0,0\n")
    with pytest.raises(robcal.InputError) as e:
        robcal.import_poses(quat, out)
    message(e, "quat.csv:2: column 'qw1'")
