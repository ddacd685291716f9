"""robcal from Python: calibration of robot manipulators from measurements.

The engine is robcal's own (the Rust library the ``robcal`` command runs):
this package turns numpy arrays and pandas DataFrames into what it takes
and its results into numpy arrays, with the same numbers, files and
one-line error messages as the command. See ``docs/python.md``.

>>> import robcal
>>> result = robcal.calibrate("data/kr270/setup.toml", "data/kr270/measurements.csv")
>>> result.parameters_frame()          # doctest: +SKIP
>>> result.model.predict(q, load_kg=250.0, com_m=[0.25, 0, 0.3])  # doctest: +SKIP

Units are the data contract's: the measurement table's columns in the
setup's ``[units]``; parameters in the units ``units`` names; the model's
joint values in rad (or m), points in m, errors in µm (``_um``).
"""

from __future__ import annotations

import os
import warnings as _warnings
from collections.abc import Mapping
from typing import Any, NamedTuple, Optional, Sequence, Union

import numpy as np

from . import _robcal
from ._robcal import CalibrationError, Error, InputError

__version__ = _robcal.__version__

__all__ = [
    "Calibration",
    "CalibrationError",
    "Compensation",
    "Error",
    "InputError",
    "Job",
    "Measurements",
    "Model",
    "NotACalibrationError",
    "Plan",
    "RobcalWarning",
    "calibrate",
    "import_figaroh_mocap",
    "import_poses",
    "plan",
]

PathLike = Union[str, "os.PathLike[str]"]


class NotACalibrationError(Error):
    """The fit did not converge, or its model fits its own data worse than
    the nominal robot: not a calibration (the command exits 1). The result
    is kept for inspection in ``.result``; ``accept_unconverged=True``
    returns it instead."""

    def __init__(self, message: str, result: "Calibration"):
        super().__init__(message)
        self.result = result


class RobcalWarning(UserWarning):
    """A warning of robcal's readers or of the model's payload rule (the
    command prints these on stderr)."""


# --------------------------------------------------------------------------
# numpy in


def _real(x: Any, name: str) -> np.ndarray:
    """`x` as a C-contiguous float64 array; integers are taken exactly,
    anything else that is not a real number is a TypeError."""
    try:
        a = np.asarray(x)
    except ValueError as e:  # ragged rows
        raise ValueError(f"{name}: not an array of numbers: {e}") from None
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{name}: expected real numbers, got an array of dtype {a.dtype}")
    return np.asarray(a, dtype=np.float64, order="C")


def _int(v: Any, name: str) -> int:
    """A whole number (not a bool), as Python's int."""
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name}: expected a whole number, got {v!r}")
    v = int(v)
    if abs(v) >= 2**62:
        raise ValueError(f"{name} = {v}: out of range")
    return v


def _number(v: Any, name: str) -> float:
    """A real number (not a bool), as Python's float."""
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a number, got {v!r}")
    return float(v)


def _joints(q: Any, names: list[str], angular: list[bool], name: str) -> Any:
    """Joint values given as a DataFrame: its joint columns by name
    (``<joint>_rad``, or ``_m`` for a prismatic joint), never by position."""
    if not hasattr(q, "columns"):
        return q
    cols = [f"{n}_{'rad' if a else 'm'}" for n, a in zip(names, angular)]
    missing = [c for c in cols if c not in q.columns]
    if missing:
        raise ValueError(
            f"{name}: no column {missing[0]!r}: a DataFrame of joint values has one column "
            f"per joint, by name and unit ({', '.join(cols)})"
        )
    return q[cols].to_numpy()


def _rows(x: Any, width: int, name: str, what: str) -> tuple[np.ndarray, bool]:
    """`x` as (n, width) rows, and whether it was one row of shape (width,)."""
    a = _real(x, name)
    if a.ndim == 1 and a.shape[0] == width:
        return a.reshape(1, width), True
    if a.ndim == 2 and a.shape[1] == width and a.shape[0] > 0:
        return a, False
    raise ValueError(f"{name}: shape {a.shape}: expected ({width},) or (n, {width}) {what}")


def _per_row(x: Any, n: int, width: int, name: str) -> list[float]:
    """One value (width 1) or vector for all rows, or one per row, flat."""
    a = _real(x, name)
    if width == 1 and a.ndim == 0:
        return [float(a)]
    if a.shape == (width,) and width > 1:
        return a.tolist()
    if (width == 1 and a.shape == (n,)) or a.shape == (n, width):
        return a.reshape(-1).tolist()
    want = "()" if width == 1 else f"({width},)"
    raise ValueError(f"{name}: shape {a.shape}: expected {want} or ({n},{'' if width == 1 else f' {width}'})")


# --------------------------------------------------------------------------
# The job and its measurements


class Measurements:
    """A measurement file or table read for a job (the contract's CSV,
    ``docs/formats.md``): every check and message of the command's reader."""

    def __init__(self, native: "_robcal.Measurements"):
        self._native = native
        for w in native.warnings:
            _warnings.warn(w, RobcalWarning, stacklevel=3)

    @property
    def file(self) -> str:
        """The file, or the name the table was given."""
        return self._native.file

    @property
    def warnings(self) -> list[str]:
        """The reader's warnings."""
        return self._native.warnings

    def __len__(self) -> int:
        return len(self._native)


def _toml(value: Any, path: str = "") -> str:
    """A setup given as a dict, as TOML text (tables, arrays of tables,
    strings, numbers, booleans, arrays)."""

    def quoted(text: str) -> str:
        out = []
        for c in text:
            if c in '"\\':
                out.append("\\" + c)
            elif ord(c) < 0x20 or ord(c) == 0x7F:
                out.append(f"\\u{ord(c):04X}")
            else:
                out.append(c)
        return '"' + "".join(out) + '"'

    def scalar(v: Any, at: str) -> str:
        if isinstance(v, np.ndarray) and v.ndim == 0:
            v = v.item()
        if isinstance(v, (bool, np.bool_)):
            return "true" if v else "false"
        if isinstance(v, (int, np.integer)):
            return str(int(v))
        if isinstance(v, (float, np.floating)):
            return repr(float(v))
        if isinstance(v, (str, os.PathLike)):
            return quoted(os.fspath(v))
        if isinstance(v, (list, tuple, np.ndarray)):
            return "[" + ", ".join(scalar(x, at) for x in v) + "]"
        raise TypeError(f"setup {at}: a {type(v).__name__} has no TOML form")

    lines: list[str] = []
    tables: list[tuple[str, Any]] = []
    for k, v in value.items():
        key = f"{path}.{k}" if path else str(k)
        if isinstance(v, Mapping):
            tables.append((key, v))
        elif isinstance(v, (list, tuple)) and v and all(isinstance(x, Mapping) for x in v):
            tables.extend((f"[{key}]", x) for x in v)
        else:
            lines.append(f"{k} = {scalar(v, key)}")
    for key, v in tables:
        head = f"[{key}]" if not key.startswith("[") else f"[{key}]"
        lines.append("")
        lines.append(head)
        body = _toml(v, key.strip("[]"))
        lines.extend(line for line in body.splitlines())
    return "\n".join(lines) + "\n"


class Job:
    """A calibration job: the setup and the robot it names.

    ``Job.load("setup.toml")`` reads the files; ``Job.from_text(setup,
    urdf)`` takes the setup as a dict or TOML text and the URDF's text."""

    def __init__(self, native: "_robcal.Job"):
        self._native = native

    @classmethod
    def load(cls, setup: PathLike) -> "Job":
        """Reads the setup file and the URDF it names."""
        return cls(_robcal.Job.load(os.fspath(setup)))

    @classmethod
    def from_text(
        cls,
        setup: Union[str, Mapping[str, Any]],
        urdf: str,
        setup_name: str = "<setup>",
        urdf_name: str = "<urdf>",
    ) -> "Job":
        """A job from memory: ``setup`` a dict (the setup file's keys) or
        TOML text, ``urdf`` the URDF's text. Without a ``robot`` key the
        URDF's name stands in for it."""
        if isinstance(setup, Mapping):
            setup = dict(setup)
            setup.setdefault("robot", urdf_name)
            setup = _toml(setup)
        elif not isinstance(setup, str):
            raise TypeError("setup: expected a dict or TOML text")
        return cls(_robcal.Job.parse(setup, urdf, setup_name, urdf_name))

    @property
    def robot_name(self) -> str:
        return self._native.robot_name

    @property
    def joint_names(self) -> list[str]:
        """The movable joints, chain order: the table's joint columns."""
        return self._native.joint_names

    @property
    def units(self) -> tuple[str, str]:
        """The table's ``(angle, length)`` units, e.g. ``("deg", "mm")``."""
        return self._native.units

    @property
    def markers(self) -> list[int]:
        return self._native.markers

    def setup_toml(self) -> str:
        """The setup as TOML text."""
        return self._native.setup_toml()

    def measurements(self, data: Any, name: Optional[str] = None) -> Measurements:
        """Measurements of this job: a CSV file's path, a pandas DataFrame,
        or a mapping of column name to values (the contract's columns:
        ``config``, ``marker``, ``load_kg``, one per joint, ``x, y, z``,
        optional ``rep``, ``t``, ``sx, sy, sz``), in the setup's units. A
        table is read by the file reader, its checks and messages; its line
        ``k`` is row ``k − 2``."""
        if isinstance(data, Measurements):
            return data
        if isinstance(data, (str, os.PathLike)):
            return Measurements(self._native.read_measurements(os.fspath(data)))
        if hasattr(data, "columns") and hasattr(data, "__getitem__") and hasattr(data, "shape"):
            columns = {str(c): data[c].to_numpy() for c in data.columns}
            default = "<DataFrame>"
        elif isinstance(data, Mapping):
            columns = {str(k): np.asarray(v) for k, v in data.items()}
            default = "<table>"
        else:
            raise TypeError(
                f"data: expected a path, a pandas DataFrame or a mapping of columns, "
                f"got {type(data).__name__}"
            )
        cols = []
        rows = None
        for k, v in columns.items():
            v = np.asarray(v)
            if v.ndim != 1:
                raise ValueError(f"column {k!r}: shape {v.shape}: expected one value per row")
            if rows is None:
                rows = v.shape[0]
            elif v.shape[0] != rows:
                raise ValueError(f"column {k!r} has {v.shape[0]} values, column {next(iter(columns))!r} {rows}")
            if v.dtype.kind in "mM":
                raise TypeError(
                    f"column {k!r}: {v.dtype} values: give numbers in the contract's units "
                    "(a time in seconds)"
                )
            if v.dtype.kind == "f" or (
                v.dtype.kind in "iu" and bool(np.all((v > -(2**53)) & (v < 2**53)))
            ):
                # Integers below 2⁵³ are exact as float64, and written back
                # without a fraction ("1", not "1.0"): no text per cell here.
                cols.append((k, np.ascontiguousarray(v, dtype=np.float64).tobytes()))
            else:
                cols.append((k, [str(x) for x in v.tolist()]))
        return Measurements(self._native.table_measurements(cols, rows or 0, name or default))

    def calibrate(
        self,
        data: Any,
        *,
        method: str = "irls",
        lambda_: Optional[float] = None,
        max_iter: int = 100,
        diagnose: bool = True,
        linear: bool = False,
        leave_out_outliers: bool = False,
        robust: bool = False,
        validate: Any = None,
        reregister: bool = False,
        accept_unconverged: bool = False,
    ) -> "Calibration":
        """``robcal calibrate`` of ``data`` (a path, DataFrame, mapping or
        Measurements): the same settings by the same names (``lambda_`` for
        ``--lambda``, ``diagnose=False`` for ``--no-diagnose``). Raises
        NotACalibrationError where the command exits 1, unless
        ``accept_unconverged``. The GIL is released while it runs."""
        max_iter = _int(max_iter, "max_iter")
        lambda_ = None if lambda_ is None else _number(lambda_, "lambda_")
        m = self.measurements(data)
        v = None if validate is None else self.measurements(validate)
        native = self._native.calibrate(
            m._native,
            method=method,
            lambda_=lambda_,
            max_iter=max_iter,
            diagnose=diagnose,
            linear=linear,
            leave_out_outliers=leave_out_outliers,
            robust=robust,
            validate=None if v is None else v._native,
            reregister=reregister,
        )
        result = Calibration(native)
        if result.failure is not None and not accept_unconverged:
            raise NotACalibrationError(
                f"not a calibration: {result.failure}; the result is kept in .result "
                "(accept_unconverged=True accepts it)",
                result,
            )
        return result


def calibrate(
    setup: Union[PathLike, Mapping[str, Any], Job],
    data: Any,
    *,
    urdf: Optional[str] = None,
    **settings: Any,
) -> "Calibration":
    """``robcal calibrate --setup SETUP --data DATA``: ``setup`` a path (the
    URDF it names is read), a Job, or with ``urdf`` (the URDF's text) a
    dict or TOML text; ``data`` a path, DataFrame or mapping of columns.
    ``settings`` as :meth:`Job.calibrate`."""
    if isinstance(setup, Job):
        job = setup
    elif urdf is not None:
        job = Job.from_text(setup, urdf)  # type: ignore[arg-type]
    elif isinstance(setup, (str, os.PathLike)):
        job = Job.load(setup)
    else:
        raise TypeError("setup: a dict or TOML text needs urdf= (the URDF's text)")
    return job.calibrate(data, **settings)


class Plan:
    """``robcal plan``'s result: the configurations to measure, in the order
    chosen, and what they predict. ``q`` (K, dof) [rad or m] and ``load_kg``
    (K,) [kg]; ``csv()`` the points CSV the command writes (``--output``),
    the same text; ``frame()`` it as a DataFrame."""

    def __init__(self, native: "_robcal.Plan", dof: int):
        self._native = native
        self.q: np.ndarray = np.frombuffer(native.q, dtype=np.float64).reshape(-1, dof).copy()
        self.load_kg: np.ndarray = np.array(native.load_kg, dtype=np.float64)
        self.criterion, self.candidates, self.exchanges = native.summary
        names, units, left_out, notes = native.parameters
        self.names: list[str] = names
        """The parameters planned for (those the pool determines)."""
        self.units: list[str] = units
        self.left_out: list[str] = left_out
        """Declared parameters no candidate determines."""
        self.notes: list[str] = notes
        planned, random = native.scores()
        self.std: np.ndarray = np.array(planned.pop("std"), dtype=np.float64)
        """Each parameter's predicted σ after measuring the plan [units]."""
        self.scores: dict = planned
        """``log_det``, ``trace_scaled``, ``min_eigenvalue_scaled``,
        ``condition``, ``predicted_rms_um`` (the command's JSON keys)."""
        self.std_random: Optional[np.ndarray] = None
        """The same from as many random candidates (None for your pool)."""
        self.scores_random: Optional[dict] = None
        if random is not None:
            self.std_random = np.array(random.pop("std"), dtype=np.float64)
            self.scores_random = random

    def csv(self) -> str:
        """The points CSV ``robcal plan --output`` writes."""
        return self._native.csv()

    def frame(self):
        """The configurations as a pandas DataFrame (the points CSV's columns)."""
        import io

        import pandas as pd

        return pd.read_csv(io.StringIO(self.csv()))

    def parameters_frame(self):
        """Predicted σ per parameter, the plan's and random poses'."""
        import pandas as pd

        d = {"std": self.std, "unit": self.units}
        if self.std_random is not None:
            d["std_random"] = self.std_random
        return pd.DataFrame(d, index=pd.Index(self.names, name="name"))


def plan(
    setup: Union[PathLike, Job],
    poses: int,
    *,
    candidates: Optional[int] = None,
    pool: Any = None,
    criterion: str = "d",
    seed: int = 0x706C616E,
    load_kg: Sequence[float] = (),
    limits: Optional[Mapping[str, tuple[float, float]]] = None,
    exchange_passes: int = 10,
    orientation_urad: Optional[float] = None,
) -> Plan:
    """``robcal plan --setup SETUP --poses K``: the ``poses`` configurations
    that determine the setup's declared model best, chosen before
    measuring. Candidates: ``candidates`` random ones within the joint
    limits (``limits={joint: (lo, hi)}`` tighter, rad or m), each with
    every mass of ``load_kg``; or your ``pool``: the points CSV's path (the
    command's ``--pool``), a DataFrame with a ``<joint>_rad``/``_m`` column
    per joint and optionally ``load_kg``, or rows of joint values (n, dof)
    with ``load_kg`` one mass for all or one per row. ``criterion``: ``d``, ``a``, ``i``, ``e`` or
    ``condition`` (docs/plan.md). ``orientation_urad``: a 6-D instrument,
    each candidate measured as a pose, its orientation's σ per axis [µrad]
    (the command's ``--orientation-urad``)."""
    job = setup if isinstance(setup, Job) else Job.load(setup)
    dof = len(job.joint_names)
    if pool is not None and candidates is not None:
        raise ValueError("candidates: random candidates are drawn without a pool; a pool is given")
    loads = _real(load_kg, "load_kg").reshape(-1).tolist()
    pool_q = pool_load = pool_path = None
    if isinstance(pool, (str, os.PathLike)):
        pool_path = os.fspath(pool)
    elif pool is not None:
        if hasattr(pool, "columns"):
            units = ["rad" if a else "m" for a in job._native.joint_is_angular]
            cols = [f"{n}_{u}" for n, u in zip(job.joint_names, units)]
            missing = [c for c in cols if c not in pool.columns]
            if missing:
                raise ValueError(f"pool: no column {missing[0]!r} (one per joint: {', '.join(cols)})")
            q = _real(pool[cols].to_numpy(), "pool")
            if "load_kg" in pool.columns:
                pool_load = _real(pool["load_kg"].to_numpy(), "pool load_kg").tolist()
        else:
            q, _ = _rows(pool, dof, "pool", "joint values")
            if loads:
                pool_load = loads  # one mass for every row, or one per row
        pool_q = np.ascontiguousarray(q, dtype=np.float64).tobytes()
    native = _robcal.plan(
        job._native,
        _int(poses, "poses"),
        candidates=1000 if candidates is None else _int(candidates, "candidates"),
        pool_q=pool_q,
        pool_load_kg=pool_load,
        pool_path=pool_path,
        criterion=criterion,
        seed=_int(seed, "seed"),
        load_kg=loads if pool is None else [],
        limits=[(str(k), _number(v[0], f"limits {k!r}"), _number(v[1], f"limits {k!r}")) for k, v in (limits or {}).items()],
        exchange_passes=_int(exchange_passes, "exchange_passes"),
        orientation_urad=None if orientation_urad is None else _number(orientation_urad, "orientation_urad"),
    )
    return Plan(native, dof)


def import_figaroh_mocap(input: PathLike, output: PathLike, job: Optional[Job] = None) -> tuple[int, int]:
    """``robcal import figaroh-mocap INPUT OUTPUT``: a FIGAROH motion-capture
    CSV into the contract's CSV (rad, m), the joints in ``job``'s chain
    order when given; ``output`` untouched on error. Returns
    ``(postures, rows)``."""
    return _robcal.import_figaroh_mocap(
        os.fspath(input), os.fspath(output), None if job is None else job._native
    )


def import_poses(
    input: PathLike,
    output: PathLike,
    split: Optional[str] = None,
    euler: Optional[str] = None,
) -> tuple[int, int]:
    """``robcal import poses INPUT OUTPUT [--split NAME] [--euler CONVENTION]``:
    the real data sets' wide pose CSV, or a 6-D export (a marker's
    orientation as ``qw<i>, qx<i>, qy<i>, qz<i>`` or Euler angles
    ``rx<i>_deg, ry<i>_deg, rz<i>_deg``), into the contract's CSV (rad, m;
    an orientation as the rotation vector ``rx, ry, rz``). ``euler`` names
    the Euler convention: ``"fixed-xyz"`` (R = Rz Ry Rx) or ``"moving-xyz"``
    (R = Rx Ry Rz). Plausibility findings (gimbal lock, radians in a
    ``_deg`` column) are ``RobcalWarning``s. Returns ``(poses, rows)``."""
    poses, rows, found = _robcal.import_poses(os.fspath(input), os.fspath(output), split, euler)
    for w in found:
        _warnings.warn(w, RobcalWarning, stacklevel=2)
    return poses, rows


# --------------------------------------------------------------------------
# Results


class Calibration:
    """A calibration's result: the report's numbers, its files and the
    calibrated robot. ``json()`` is the command's ``--json`` text, to the
    byte; the arrays are the same numbers."""

    def __init__(self, native: "_robcal.Calibration"):
        self._native = native
        self._dict: Optional[dict] = None
        self._files: Optional[dict] = None
        params = native.parameters
        self.names: list[str] = [p[0] for p in params]
        """The parameters' names (the contract's)."""
        self.values: np.ndarray = np.array([p[1] for p in params], dtype=np.float64)
        """The estimates, in ``units``."""
        self.std: np.ndarray = np.array([p[2] for p in params], dtype=np.float64)
        """Their standard deviations (the sandwich, eq. 8, 11)."""
        self.units: list[str] = [p[3] for p in params]
        self.determined: np.ndarray = np.array([p[4] for p in params], dtype=bool)
        """False where the estimate is within 2σ of 0."""
        n = len(params)
        self.covariance: np.ndarray = np.frombuffer(native.covariance, dtype=np.float64).reshape(n, n).copy()
        """The covariance, in the product of the two parameters' units."""

    def json(self) -> str:
        """The contract's JSON (``robcal calibrate --json``), the same text."""
        return self._native.json()

    def to_dict(self) -> dict:
        """The JSON as a dict."""
        if self._dict is None:
            import json

            self._dict = json.loads(self.json())
        return self._dict

    def text(self) -> str:
        """The text report (``robcal calibrate``)."""
        return self._native.text()

    def __str__(self) -> str:
        return self.text()

    def __repr__(self) -> str:
        d = self.to_dict()
        h = d["heldout_rms_um"]
        held = "no held-out RMS" if h is None else f"held-out {h:.4g} µm"
        return (
            f"<robcal.Calibration: {len(self.names)} parameters, RMS {d['rms_um']:.4g} µm, "
            f"{held}, {len(d['effects'])} effects added>"
        )

    @property
    def failure(self) -> Optional[str]:
        """Why the result is not a calibration, or None."""
        return self._native.failure

    @property
    def converged(self) -> bool:
        return self.to_dict()["converged"]

    @property
    def rms_um(self) -> float:
        """The residuals' RMS [µm]."""
        return self.to_dict()["rms_um"]

    @property
    def heldout_rms_um(self) -> Optional[float]:
        """Leave-one-configuration-out RMS [µm]."""
        return self.to_dict()["heldout_rms_um"]

    @property
    def nominal(self) -> dict:
        """The nominal robot's error: ``rms_um``, ``mean_um``, ``max_um``."""
        return self.to_dict()["nominal"]

    @property
    def effects(self) -> list[dict]:
        """The closed loop's steps: each effect added, its p-value and the
        RMS before and after [µm]."""
        return self.to_dict()["effects"]

    @property
    def identifiability(self) -> list[dict]:
        """Parameters the data cannot tell apart: each left out, and what
        absorbs it."""
        return self.to_dict()["identifiability"]

    @property
    def validation(self) -> Optional[dict]:
        return self.to_dict()["validation"]

    @property
    def warnings(self) -> list[str]:
        return self.to_dict()["warnings"]

    @property
    def notes(self) -> list[str]:
        return self.to_dict().get("notes", [])

    def parameters_frame(self):
        """The parameters as a pandas DataFrame (index: name; columns:
        value, std, unit, determined)."""
        import pandas as pd

        return pd.DataFrame(
            {"value": self.values, "std": self.std, "unit": self.units, "determined": self.determined},
            index=pd.Index(self.names, name="name"),
        )

    def output_files(self, keep_nominal_markers: bool = False) -> dict[str, str]:
        """``robcal calibrate --output DIR``'s files by name, as text:
        ``robot.urdf``, ``model.json``, ``report.html`` and the figures."""
        if keep_nominal_markers:
            return self._native.output_files(True)
        if self._files is None:
            self._files = self._native.output_files(False)
        return self._files

    @property
    def urdf(self) -> str:
        """The calibrated URDF (``robot.urdf``)."""
        return self.output_files()["robot.urdf"]

    @property
    def model_json(self) -> str:
        """``model.json``: the report, its covariance and the predictor."""
        return self.output_files()["model.json"]

    @property
    def report_html(self) -> str:
        """``report.html``: one self-contained page."""
        return self.output_files()["report.html"]

    @property
    def figures(self) -> dict[str, str]:
        """The report's figures (SVG text) by file name."""
        return {k: v for k, v in self.output_files().items() if k.endswith(".svg")}

    def write(self, directory: PathLike, keep_nominal_markers: bool = False) -> None:
        """Writes ``--output DIR``'s files into ``directory``, all or nothing."""
        self._native.write(os.fspath(directory), keep_nominal_markers)

    @property
    def model(self) -> "Model":
        """The calibrated robot (what ``model.json`` holds)."""
        return Model(self._native.model())


class Compensation(NamedTuple):
    """The compensated joint commands of :meth:`Model.compensate`."""

    q: np.ndarray
    """The commands, (n, dof) [rad or m]."""
    error_um: np.ndarray
    """The error the model leaves at each target [µm]."""
    error_urad: Optional[np.ndarray]
    """The orientation's [µrad], for pose targets."""
    iterations: np.ndarray
    """Newton's steps per target."""


class Model:
    """A calibrated robot: where a marker settles for joint values and a
    payload (``robcal predict``), and the joint commands that reach
    targets (``robcal compensate``). SI units: rad (m for prismatic
    joints), m, kg."""

    def __init__(self, native: "_robcal.Model"):
        self._native = native

    @classmethod
    def load(cls, path: PathLike) -> "Model":
        """Reads ``model.json``."""
        return cls(_robcal.Model.load(os.fspath(path)))

    @classmethod
    def from_json(cls, text: str) -> "Model":
        """A model from ``model.json``'s text."""
        return cls(_robcal.Model.from_json(text))

    @property
    def joint_names(self) -> list[str]:
        return self._native.joint_names

    @property
    def dof(self) -> int:
        return len(self._native.joint_names)

    @property
    def markers(self) -> dict[int, np.ndarray]:
        """The calibrated markers [m, tip frame] by id."""
        return {i: np.array(p) for i, p in self._native.markers}

    @property
    def thermal_expansion(self) -> Optional[tuple[float, float]]:
        """The links' thermal expansion, ``(alpha [1/K], the temperature
        [degC] the lengths hold at)``, or None when the calibration had no
        temperature column."""
        return self._native.thermal_expansion

    def at_temperature(self, temp_c: float) -> "Model":
        """The robot at ``temp_c`` [degC]: every length from the first
        joint out stretched by ``1 + alpha (T - T_ref)``
        (``robcal predict --temperature-c``)."""
        return Model(self._native.at_temperature(float(temp_c)))

    def _warn_payload(self, load: list[float]) -> None:
        w = self._native.payload_warning(load)
        if w is not None:
            _warnings.warn(w.replace("(line ", "(row "), RobcalWarning, stacklevel=3)

    def predict(
        self,
        q: Any,
        load_kg: Any = 0.0,
        com_m: Any = (0.0, 0.0, 0.0),
        marker: Optional[int] = None,
    ) -> np.ndarray:
        """Where the marker settles [m, measurement frame] at joint values
        ``q`` ((dof,) or (n, dof)) with the payload ``load_kg`` (one, or one
        per row) at ``com_m`` [m, tip frame] ((3,) or (n, 3)): (3,) or
        (n, 3). ``marker`` may be left out when the model has one."""
        return self._predict(q, load_kg, com_m, marker, False)

    def predict_orientation(
        self,
        q: Any,
        load_kg: Any = 0.0,
        com_m: Any = (0.0, 0.0, 0.0),
        marker: Optional[int] = None,
    ) -> np.ndarray:
        """The orientation a 6-D instrument measures beside ``predict``'s
        point: the tip frame turned by the identified tool frame, at the
        robot's equilibrium, as a rotation vector (axis × angle) [rad,
        measurement frame], ``robcal predict --orientation``'s ``rx_rad,
        ry_rad, rz_rad``. Arguments as ``predict``'s: (3,) or (n, 3)."""
        return self._predict(q, load_kg, com_m, marker, True)

    def _predict(self, q: Any, load_kg: Any, com_m: Any, marker: Optional[int], orientation: bool) -> np.ndarray:
        q = _joints(q, self.joint_names, self._native.joint_is_angular, "q")
        rows, one = _rows(q, self.dof, "q", "joint values")
        n = rows.shape[0]
        load = _per_row(load_kg, n, 1, "load_kg")
        com = _per_row(com_m, n, 3, "com_m")
        marker = None if marker is None else _int(marker, "marker")
        out = self._native.predict(rows.tobytes(), load, com, marker, orientation)
        self._warn_payload(load if len(load) == n else load * n)
        p = np.frombuffer(out, dtype=np.float64).reshape(n, 3).copy()
        return p[0] if one else p

    def compensate(
        self,
        targets_m: Any,
        q_start: Any,
        load_kg: Any = 0.0,
        com_m: Any = (0.0, 0.0, 0.0),
        marker: Optional[int] = None,
        rotation_rad: Any = None,
        tolerance_um: float = 0.1,
        max_iter: int = 20,
    ) -> Compensation:
        """The joint commands whose loaded, deflected robot puts the marker
        on ``targets_m`` [m, measurement frame] ((3,) or (n, 3)), Newton from
        ``q_start`` (e.g. the nominal inverse kinematics); with
        ``rotation_rad`` (rotation vectors of the tip frame) pose targets."""
        q_start = _joints(q_start, self.joint_names, self._native.joint_is_angular, "q_start")
        q, one = _rows(q_start, self.dof, "q_start", "joint values")
        n = q.shape[0]
        t, _ = _rows(targets_m, 3, "targets_m", "points")
        if t.shape[0] != n:
            raise ValueError(f"targets_m: {t.shape[0]} targets for {n} rows of q_start")
        rot = None
        if rotation_rad is not None:
            r, _ = _rows(rotation_rad, 3, "rotation_rad", "rotation vectors")
            if r.shape[0] != n:
                raise ValueError(f"rotation_rad: {r.shape[0]} rotations for {n} rows of q_start")
            rot = r.tobytes()
        load = _per_row(load_kg, n, 1, "load_kg")
        com = _per_row(com_m, n, 3, "com_m")
        marker = None if marker is None else _int(marker, "marker")
        qs, err, err_rot, its = self._native.compensate(
            t.tobytes(),
            q.tobytes(),
            load,
            com,
            marker,
            rot,
            _number(tolerance_um, "tolerance_um"),
            _int(max_iter, "max_iter"),
        )
        self._warn_payload(load if len(load) == n else load * n)
        qs = np.frombuffer(qs, dtype=np.float64).reshape(n, self.dof).copy()
        err = np.array(err)
        err_rot = None if err_rot is None else np.array(err_rot)
        its = np.array(its)
        if one:
            return Compensation(qs[0], err[0], None if err_rot is None else err_rot[0], its[0])
        return Compensation(qs, err, err_rot, its)
