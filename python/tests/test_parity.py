"""The Python package is the command's engine: on the bundled jobs its
results are the command's, byte for byte (the JSON, every --output file)
or to the bit (predict, compensate), whatever the input's form (files, a
DataFrame, columns, a setup from memory). And the GIL is released while
it calibrates."""

import threading
import time

import numpy as np
import pandas as pd
import pytest

import robcal
from conftest import run

KR270 = "data/kr270/setup.toml"
KR270_DATA = "data/kr270/measurements.csv"


@pytest.mark.parametrize(
    "setup, args, kwargs",
    [
        (KR270, [], {}),
        (KR270, ["--method", "ols"], {"method": "ols"}),
        (KR270, ["--linear", "--no-diagnose"], {"linear": True, "diagnose": False}),
        ("data/kr270/setup-naive.toml", [], {}),
        ("data/kr270/setup-naive.toml", ["--robust", "--lambda", "0.5"], {"robust": True, "lambda_": 0.5}),
    ],
)
def test_the_json_is_the_commands(cli, repo, setup, args, kwargs):
    want = run(cli, "calibrate", "--setup", setup, "--data", KR270_DATA, "--json", *args)
    got = robcal.calibrate(repo / setup, repo / KR270_DATA, **kwargs)
    assert got.json() == want
    # The arrays are the JSON's numbers.
    d = got.to_dict()
    assert got.names == [p["name"] for p in d["parameters"]]
    assert np.array_equal(got.values, [p["value"] for p in d["parameters"]])
    assert np.array_equal(got.std, [p["std"] for p in d["parameters"]])
    assert np.allclose(np.sqrt(np.diag(got.covariance)), got.std, rtol=1e-12, atol=0)


def test_plane_contacts_from_a_frame_are_the_commands(cli, repo):
    """The README's plane-contact job: the command's JSON, from the path
    and from a DataFrame (pandas reads the empty x, y, z cells as NaN:
    empty cells again)."""
    setup, data = "data/kr270/setup-contacts.toml", "data/kr270/contacts.csv"
    want = run(cli, "calibrate", "--setup", setup, "--data", data, "--json")
    assert robcal.calibrate(repo / setup, repo / data).json() == want
    frame = pd.read_csv(repo / data)
    assert frame["anchor"].isna().all()
    assert robcal.calibrate(repo / setup, frame).json() == want
    import json

    scalars = json.loads(want)["scalars"]
    assert scalars["rows"] == len(frame)


def test_every_output_file_is_the_commands(cli, repo, tmp_path, monkeypatch):
    out = tmp_path / "out"
    run(cli, "calibrate", "--setup", KR270, "--data", KR270_DATA, "--output", str(out))
    # The page names the files as given: the same relative paths.
    monkeypatch.chdir(repo)
    result = robcal.calibrate(KR270, KR270_DATA)
    files = result.output_files()
    assert sorted(files) == sorted(p.name for p in out.iterdir())
    for name, text in files.items():
        assert text == (out / name).read_text(), name
    # write(): the same files, all of them.
    mine = tmp_path / "mine"
    result.write(mine)
    for name in files:
        assert (mine / name).read_bytes() == (out / name).read_bytes(), name
    assert result.urdf == files["robot.urdf"]
    assert result.model_json == files["model.json"]
    assert "<!DOCTYPE html>" in result.report_html
    assert set(result.figures) == {n for n in files if n.endswith(".svg")}


def test_a_table_or_a_setup_from_memory_is_the_file(repo):
    want = robcal.calibrate(repo / KR270, repo / KR270_DATA).json()
    df = pd.read_csv(repo / KR270_DATA)
    assert robcal.calibrate(repo / KR270, df).json() == want
    columns = {c: df[c].to_numpy() for c in df.columns}
    assert robcal.calibrate(repo / KR270, columns).json() == want
    # The setup as text and as a dict, the URDF as text.
    setup_text = (repo / KR270).read_text()
    urdf = (repo / "data/kr270/kr270.urdf").read_text()
    assert robcal.calibrate(setup_text, df, urdf=urdf).json() == want
    job = robcal.Job.load(repo / KR270)
    import tomllib

    as_dict = tomllib.loads(job.setup_toml())
    assert robcal.calibrate(as_dict, df, urdf=urdf).json() == want
    # The calibrated URDF of a job from memory is the file job's.
    from_text = robcal.Job.from_text(setup_text, urdf).calibrate(df)
    assert from_text.urdf == robcal.calibrate(repo / KR270, repo / KR270_DATA).urdf


def test_validation_is_the_commands(cli, repo):
    want = run(
        cli, "calibrate", "--setup", KR270, "--data", KR270_DATA,
        "--validate", KR270_DATA, "--reregister", "--json",
    )
    got = robcal.calibrate(repo / KR270, repo / KR270_DATA, validate=repo / KR270_DATA, reregister=True)
    assert got.json() == want
    # Deflections only (no absolute point): nothing to re-register.
    assert got.validation["points"] == 270 and got.validation["reregistered"] is False


def test_predict_and_compensate_are_the_commands(cli, repo, tmp_path):
    out = tmp_path / "out"
    run(cli, "calibrate", "--setup", KR270, "--data", KR270_DATA, "--output", str(out))
    model = robcal.Model.load(out / "model.json")
    assert model.joint_names == ["a1", "a2", "a3", "a4", "a5", "a6"]
    # predict: the poses file's rows, one call.
    want = pd.read_csv(
        pd.io.common.StringIO(
            run(cli, "predict", "--model", str(out / "model.json"), "--poses", "data/kr270/poses.csv")
        )
    )
    q = want[[f"{j}_rad" for j in model.joint_names]].to_numpy()
    com = want[["com_x_m", "com_y_m", "com_z_m"]].to_numpy()
    markers = want["marker"].to_numpy()
    for m in np.unique(markers):
        rows = markers == m
        got = model.predict(q[rows], load_kg=want["load_kg"].to_numpy()[rows], com_m=com[rows], marker=int(m))
        assert np.array_equal(got, want.loc[rows, ["x_m", "y_m", "z_m"]].to_numpy())
    # One row in, one point out.
    assert model.predict(q[0], load_kg=want["load_kg"][0], com_m=com[0], marker=int(markers[0])).shape == (3,)
    # compensate: the targets file's rows.
    want = pd.read_csv(
        pd.io.common.StringIO(
            run(cli, "compensate", "--model", str(out / "model.json"), "--targets", "data/kr270/targets.csv")
        )
    )
    targets = pd.read_csv(repo / "data/kr270/targets.csv")
    cols = [f"{j}_rad" for j in model.joint_names]
    for m in np.unique(targets["marker"]):
        rows = (targets["marker"] == m).to_numpy()
        c = model.compensate(
            targets.loc[rows, ["x_m", "y_m", "z_m"]].to_numpy(),
            targets.loc[rows, cols].to_numpy(),
            load_kg=targets.loc[rows, "load_kg"].to_numpy(),
            com_m=targets.loc[rows, ["com_x_m", "com_y_m", "com_z_m"]].to_numpy(),
            marker=int(m),
        )
        assert np.array_equal(c.q, want.loc[rows, cols].to_numpy())
        assert np.allclose(c.error_um, want.loc[rows, "error_um"].to_numpy(), rtol=0, atol=1e-6)
        assert np.array_equal(c.iterations, want.loc[rows, "iterations"].to_numpy())
    # The model of a result is the model file's.
    result = robcal.calibrate(repo / KR270, repo / KR270_DATA)
    assert np.array_equal(result.model.predict(q, 250.0, com, marker=1), model.predict(q, 250.0, com, marker=1))


def test_a_poses_orientation_is_the_commands(cli, repo, tmp_path):
    """Model.predict_orientation is ``robcal predict --orientation``'s
    rx_rad, ry_rad, rz_rad, to the bit, on the README's 6-D pose job."""
    out = tmp_path / "out"
    run(cli, "calibrate", "--setup", "data/kr270/setup-6d.toml", "--data", "data/kr270/poses-6d.csv",
        "--output", str(out))
    model = robcal.Model.load(out / "model.json")
    data = pd.read_csv(repo / "data/kr270/poses-6d.csv")
    cols = [f"{j}_rad" for j in model.joint_names]
    poses = tmp_path / "poses.csv"
    data[model.joint_names].set_axis(cols, axis=1).assign(marker=1)[["marker"] + cols].to_csv(
        poses, index=False, float_format="%.17g")
    want = pd.read_csv(pd.io.common.StringIO(
        run(cli, "predict", "--model", str(out / "model.json"), "--poses", str(poses), "--orientation")))
    q = want[cols].to_numpy()
    got = model.predict_orientation(q)
    assert got.shape == (len(data), 3)
    assert np.array_equal(got, want[["rx_rad", "ry_rad", "rz_rad"]].to_numpy())
    assert np.array_equal(model.predict(q), want[["x_m", "y_m", "z_m"]].to_numpy())
    assert model.predict_orientation(q[0]).shape == (3,)


def test_the_robot_at_a_temperature_is_the_commands(cli, repo, tmp_path):
    out = tmp_path / "out"
    run(cli, "calibrate", "--setup", KR270, "--data", KR270_DATA, "--no-diagnose", "--output", str(out))
    text = (out / "model.json").read_text()
    model = robcal.Model.from_json(text)
    assert model.thermal_expansion is None
    with pytest.raises(robcal.CalibrationError, match="no thermal_expansion"):
        model.at_temperature(30.0)
    # The KR-270 had no temperature column: the expansion added by hand.
    import json

    d = json.loads(text)
    d["predictor"]["thermal_expansion"] = {"alpha_per_k": 12e-6, "reference_c": 21.5}
    (out / "warm.json").write_text(json.dumps(d))
    model = robcal.Model.load(out / "warm.json")
    assert model.thermal_expansion == (12e-6, 21.5)
    want = pd.read_csv(
        pd.io.common.StringIO(
            run(cli, "predict", "--model", str(out / "warm.json"), "--poses", "data/kr270/poses.csv",
                "--temperature-c", "35")
        )
    )
    q = want[[f"{j}_rad" for j in model.joint_names]].to_numpy()
    com = want[["com_x_m", "com_y_m", "com_z_m"]].to_numpy()
    m = int(want["marker"][0])
    rows = (want["marker"] == m).to_numpy()
    got = model.at_temperature(35).predict(q[rows], load_kg=want["load_kg"].to_numpy()[rows], com_m=com[rows], marker=m)
    assert np.array_equal(got, want.loc[rows, ["x_m", "y_m", "z_m"]].to_numpy())
    with pytest.raises(robcal.CalibrationError, match="outside"):
        model.at_temperature(400)


def test_a_tiago_session_is_the_commands(cli, repo, shared, tmp_path):
    session = shared / "datasets/tiago-mocap/qualisys_2021-11-30_static_postures.csv"
    by_cli = tmp_path / "cli.csv"
    run(cli, "import", "figaroh-mocap", str(session), str(by_cli))
    by_py = tmp_path / "py.csv"
    assert robcal.import_figaroh_mocap(session, by_py) == (37, 148)
    assert by_py.read_bytes() == by_cli.read_bytes()
    setup = "data/tiago/setup.toml"
    want = run(cli, "calibrate", "--setup", setup, "--data", str(by_cli), "--json")
    assert robcal.calibrate(repo / setup, by_py).json() == want


def test_the_gil_is_released_while_it_calibrates(repo):
    """A Python thread keeps running during a calibration: the longest it
    waits between two of its steps is a small part of the call (it would be
    all of it if the call held the GIL)."""
    df = pd.read_csv(repo / KR270_DATA)
    # Forty copies of the data set, each its own configurations: a call of
    # a few hundred milliseconds.
    big = pd.concat([df.assign(config=df["config"] + 1000 * k) for k in range(40)], ignore_index=True)
    job = robcal.Job.load(repo / KR270)
    data = job.measurements(big)
    t0 = time.perf_counter()
    job.calibrate(data, diagnose=False)
    alone = time.perf_counter() - t0
    stamps = []
    done = threading.Event()

    def tick():
        while not done.is_set():
            stamps.append(time.perf_counter())

    t = threading.Thread(target=tick)
    t.start()
    try:
        t0 = time.perf_counter()
        job.calibrate(data, diagnose=False)
        call = time.perf_counter() - t0
    finally:
        done.set()
        t.join()
    during = [s for s in stamps if t0 <= s <= t0 + call]
    gaps = np.diff(during)
    assert alone > 0.05 and call > 0.05, (alone, call)
    assert len(during) > 100, len(during)
    assert gaps.max() < 0.5 * call, (gaps.max(), call)


@pytest.mark.parametrize(
    "setup, args, kwargs",
    [
        ("data/kr270/setup.toml", ["--poses", "12", "--load-kg", "250"], {"poses": 12, "load_kg": [250.0]}),
        (
            "data/kr270/setup.toml",
            ["--poses", "8", "--load-kg", "0", "--load-kg", "250", "--criterion", "a", "--candidates", "300",
             "--limit", "a2=-1.2:-0.2", "--seed", "7"],
            {"poses": 8, "load_kg": [0.0, 250.0], "criterion": "a", "candidates": 300,
             "limits": {"a2": (-1.2, -0.2)}, "seed": 7},
        ),
        (
            "data/kr270/setup-6d.toml",
            ["--poses", "8", "--candidates", "300", "--orientation-urad", "30"],
            {"poses": 8, "candidates": 300, "orientation_urad": 30.0},
        ),
    ],
)
def test_a_plan_is_the_commands(cli, repo, tmp_path, setup, args, kwargs):
    out = tmp_path / "plan.csv"
    import json

    want = json.loads(run(cli, "plan", "--setup", setup, *args, "--output", str(out), "--json"))
    got = robcal.plan(repo / setup, **kwargs)
    assert got.csv() == out.read_text()
    assert got.names == [p["name"] for p in want["parameters"]]
    assert np.array_equal(got.std, [p["std"] for p in want["parameters"]])
    assert np.array_equal(got.std_random, [p["std_random"] for p in want["parameters"]])
    assert got.scores == want["plan"] and got.scores_random == want["random"]
    assert (got.criterion, got.candidates, got.exchanges) == (want["criterion"], want["candidates"], want["exchanges"])
    frame = got.frame()
    assert np.array_equal(frame[[c for c in frame.columns if c.endswith("_rad")]].to_numpy(), got.q)
    assert np.array_equal(frame["load_kg"].to_numpy(), got.load_kg)


def test_a_plan_from_a_pool_is_the_commands(cli, repo, tmp_path):
    out = tmp_path / "plan.csv"
    import json

    pool = "data/kr270/poses.csv"
    want = json.loads(run(cli, "plan", "--setup", KR270, "--poses", "6", "--pool", pool, "--output", str(out), "--json"))
    got = robcal.plan(repo / KR270, 6, pool=pd.read_csv(repo / pool))
    assert got.csv() == out.read_text()
    assert np.array_equal(got.std, [p["std"] for p in want["parameters"]])
    assert got.std_random is None and want["random"] is None
