"""Touchstone: recognize a known object and localize it in 6 DOF from touch alone.

The Python face of Touchstone's C++ library (not of the command line)::

    import touchstone as ts
    db = ts.Database("build/dev45.h5")
    log = ts.simulate(db, "bunny", grasps=20, noise="underwater", seed=3)
    rec = ts.Recognizer(db, seed=1)
    for step in rec.recognize_log(log):        # what `touchstone recognize --log` answers
        print(step.step, step.object, step.posterior, step.position_error_m)

    rec.reset()
    r = rec.step(contacts, free)               # your own N x 3 arrays (world frame, metres)
    r.pose                                     # 4 x 4 T_world_object

Errors of the library raise :class:`Error` (its ``message``, ``file`` and ``field``); long
calls release the GIL, so recognizers in several Python threads run in parallel.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

import numpy as np

from . import _touchstone as _ts

__version__: str = _ts.__version__
Error = _ts.Error
Database = _ts.Database
TactileLog = _ts.TactileLog
Exploration = _ts.Exploration
read_log = _ts.read_log
set_threads = _ts.set_threads

__all__ = [
    "Error", "Database", "TactileLog", "Exploration", "Hypothesis", "StepResult", "Recognizer",
    "read_log", "simulate", "parameters", "build_database", "run_experiment", "report", "read_runs",
    "set_threads",
    "__version__",
]


@dataclass(frozen=True)
class Hypothesis:
    """One hypothesis of the recognizer's state: an object at a pose with its weight."""

    object: str
    object_index: int
    pose: np.ndarray          # 4 x 4, T_world_object
    log_weight: float         # ln wt (Eq. 6)
    weight: float
    born: int                 # the step that created it


@dataclass(frozen=True)
class StepResult:
    """One recognition step: the answer (the best hypothesis), the posterior over objects, the
    state, and, for a log with ground truth, the errors as `touchstone recognize` reports them."""

    step: int
    valid: bool                           # at least one hypothesis
    object: Optional[str]                 # the answer's object (None: no hypothesis)
    object_index: Optional[int]
    pose: Optional[np.ndarray]            # 4 x 4 T_world_object of the answer
    log_weight: Optional[float]
    weight: Optional[float]
    posterior: Optional[float]            # posterior of the answer's object
    posteriors: np.ndarray                # per database object
    hypotheses: List[Hypothesis]          # the state, best first
    contacts: int
    free_points: int
    unobservable_dof: int
    pose_ambiguous: bool
    candidates: int
    times_s: Dict[str, float]             # per stage and "total"; "stage.NAME" per pipeline stage run
    stages_ran: List[str] = field(default_factory=list)   # the step's pipeline stages that ran
    stages_skipped: List[Dict[str, str]] = field(default_factory=list)  # {"stage", "reason"}: left out
    # unobservable_dof judged by the contacts' normals, or on the answer's surface (too few normals)
    observability: str = "contact_normals"
    correct: Optional[bool] = None        # the log's object was named (None: truth unknown)
    position_error_m: Optional[float] = None
    orientation_error_deg: Optional[float] = None
    symmetric_orientation_error_deg: Optional[float] = None
    # The support under the object (params={"support.mode": "plane"} or "cylinder"): {"shape":
    # "plane", "normal" (unit, up, world), "offset_m" (the plane normal . x = offset_m)} or
    # {"shape": "cylinder", "axis" (unit), "point" (on the axis), "radius_m"}, with the "contacts"
    # and "grasps" it explains, set aside; None: none found or not looked for
    support: Optional[Dict[str, Any]] = None
    # Whether the support was found ("found") or the test at which the candidate with the most
    # contacts on it failed ("no_candidate", "few_contacts", "few_grasps", "side_unclear",
    # "rest_not_above", "free_behind"); None: not looked for
    support_verdict: Optional[str] = None
    # What explains each contact of the step's cloud (support.mode on or evaluate.outlier_m > 0),
    # one uint8 a contact: 0 the answer's, 1 the support's, 2 unexplained; None: not labelled
    attribution: Optional[Any] = None
    # The set answer with a calibration (Recognizer(calibration=...)): {"alpha", "informative",
    # "size", "calibrated_step", "members": [{"objects", "p_value", "log_weight_gap"}]}; a member
    # without hypotheses (in the set by the shape prior) has "log_weight_gap" None and "prior_gap"
    answer_set: Optional[Dict[str, Any]] = None
    # Recognizer(explain=True): why the answer won over its best rival, as `recognize --explain`
    # gives it: {"decided_by", "hypotheses": [{"role", "object", "rank", "pose", "log_weight",
    # "contact_log_weight", "free_log_weight", "floor_log_weight", "free_points_checked", "offset_rms_m",
    # "contact_rms_sigma", "contacts_beyond_3_sigma", "twin_score", "posterior"}, ...]}
    explanation: Optional[Dict[str, Any]] = None
    _raw: Dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @staticmethod
    def _of(d: Dict[str, Any]) -> "StepResult":
        hs = [Hypothesis(**h) for h in d["hypotheses"]]
        return StepResult(**{**d, "hypotheses": hs}, _raw=d)


class Recognizer:
    """The sequential recognizer (BRICPSF by default) over a database.

    ``preset`` is ``"improved"`` (Touchstone's extensions, the default of the command) or
    ``"paper"``; ``params`` sets method parameters by their keys (``touchstone.parameters()``,
    the names of ``touchstone params``), e.g. ``{"ransac.object_draws": 60}``; ``only`` limits
    the answer to these object names. Same database, settings and seed: the same answers as
    ``touchstone recognize`` for any thread count. ``calibration``: a file of ``touchstone
    calibrate`` with answer sets, so that each step's ``answer_set`` holds the touched object's
    class with probability at least 1 - ``alpha`` (default: the file's). ``explain``: each step's
    ``explanation`` says why the answer won over its best rival (changes no answer).
    """

    def __init__(self, db: Database, preset: str = "improved", method: str = "bricpsf", seed: int = 1,
                 params: Optional[Mapping[str, Any]] = None, only: Optional[Sequence[str]] = None,
                 calibration: Optional[str] = None, alpha: Optional[float] = None,
                 explain: bool = False) -> None:
        self._impl = _ts.Recognizer(db, preset, method, seed, dict(params or {}),
                                    None if only is None else list(only),
                                    None if calibration is None else str(calibration), alpha, bool(explain))

    def step(self, contacts: Any, free: Any = None, grasps: Optional[Sequence[Any]] = None,
             hand_free: Optional[Sequence[Any]] = None, pivots: Any = None) -> StepResult:
        """One exploration step with the cumulative contacts (N x 3, world frame, metres), the
        free-space points (M x 3, or None) and optionally the same contacts grouped by grasp (a
        list of K_g x 3 arrays: the per-grasp offsets of the evaluation take out each grasp's
        arm error). With grasps, ``hand_free`` (one M_g x 3 array per grasp: the points its hand
        held free, which the support stage and the near-twin verification read) and ``pivots``
        (G x 3: the point each grasp's arm error turns about) complete what ``recognize_log``
        gives the recognizer: ``Exploration``'s ``grasps()``, ``hand_free()`` and ``pivots()``
        passed together give its answers."""
        return StepResult._of(self._impl.step(contacts, free, grasps, hand_free, pivots))

    def recognize_log(self, log: TactileLog, steps: int = 0) -> List[StepResult]:
        """Every step of a tactile log (the first ``steps`` grasps; 0: all), fused and recognized
        exactly as ``touchstone recognize --log`` does, from a fresh state."""
        return [StepResult._of(d) for d in self._impl.recognize_log(log, steps)]

    def reset(self) -> None:
        """Forget the hypotheses: the next step is step 1."""
        self._impl.reset()

    @property
    def settings(self) -> Dict[str, float]:
        """The method parameters in effect, as result files store them."""
        return self._impl.settings

    @property
    def hypotheses(self) -> List[Hypothesis]:
        """The current state, best first."""
        return [Hypothesis(**h) for h in self._impl.hypotheses]


def simulate(db: Database, object: str, grasps: int = 20, noise: str = "underwater", sensors: int = 1,
             seed: int = 1, params: Optional[Mapping[str, Any]] = None) -> TactileLog:
    """Simulate ``grasps`` random grasps of the default gripper on a database object at a random
    pose (what ``touchstone simulate`` writes); ``params``: simulator parameters by key (the
    noise overrides, ``sensing = "probe"``, ...). The log as simulated: written and read back
    (``TactileLog.write``, ``read_log``) it is what ``touchstone simulate`` writes, with its arm
    poses rounded in the last bit (the file stores each pose as a translation and a unit
    quaternion), which is enough to change later RANSAC draws: compare recognitions of the same
    file."""
    return _ts.simulate(db, object, grasps, noise, sensors, seed, dict(params or {}))


def parameters(kind: Optional[str] = None) -> List[Dict[str, Any]]:
    """The declared parameters (``touchstone params --json``): key, kind, unit, range, the
    presets' defaults, help. ``kind``: "method", "simulator" or "experiment" to select."""
    ps = json.loads(_ts.parameters_json())
    if isinstance(ps, dict) and "parameters" in ps:
        ps = ps["parameters"]
    return [p for p in ps if kind is None or p.get("kind") == kind]


def run_experiment(db: str, out: str, config: Optional[str] = None, set: Optional[Mapping[str, Any]] = None,
                   threads: int = 0, resume: bool = False,
                   progress: Optional[Callable[[int, int, Optional[float]], Any]] = None) -> Dict[str, Any]:
    """Run an experiment (``touchstone experiment``) into the run store ``out``: the configuration
    file ``config`` (optional), then ``set`` (any configuration key, as ``--set KEY=VALUE``; a
    list for a sweep key). Returns the report (``touchstone report --json``).

    ``progress(done, total, seconds_left)`` is called after each stored run (``seconds_left`` is
    None before the first). An exception it raises stops the experiment: the runs finished are
    in ``out`` (``resume=True`` continues) and the exception is raised again."""
    return json.loads(_ts.run_experiment_json(db, out, config or "", dict(set or {}), threads, resume, progress))


def _error(message: str, file: str = "", field: str = "") -> Error:
    """An Error as the library raises them: its text, and message, file and field."""
    e = Error(f"{message} ({file}{', ' + field if field else ''})" if file else message)
    e.message, e.file, e.field = message, file, field
    return e


def _write_off(path: str, vertices: Any, faces: Any, name: str, out: str, field: str) -> None:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise _error(f"vertices of {name!r}: expected a V x 3 array, got shape {v.shape}", out, field)
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or not np.issubdtype(f.dtype, np.integer):
        raise _error(f"faces of {name!r}: expected an F x 3 array of vertex indices, got shape {f.shape} "
                     f"({f.dtype})", out, field)
    if not np.all(np.isfinite(v)):
        raise _error(f"vertices of {name!r}: not all finite", out, field)
    if f.min() < 0 or f.max() >= len(v):
        raise _error(f"faces of {name!r}: an index outside 0..{len(v) - 1}", out, field)
    with open(path, "w", encoding="ascii") as stream:
        stream.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(stream, v, fmt="%.17g")
        np.savetxt(stream, np.hstack([np.full((len(f), 1), 3), f.astype(np.int64)]), fmt="%d")


def build_database(out: str, meshes: Any = None, *, manifest: Optional[str] = None,
                   params: Optional[Mapping[str, Any]] = None, scale: str = "fit", units: str = "m",
                   seed: int = 1, congruence_tolerance: float = 0.01, threads: int = 0,
                   progress: Optional[Callable[[int, int, Optional[float]], Any]] = None) -> Database:
    """Build an object database into ``out`` (HDF5), as ``touchstone db build`` does, and open it.

    ``meshes``: a folder of mesh files (any format Assimp reads; names from the file names); or a
    sequence whose items are a mesh file path, a ``(name, path)`` pair or a ``(name, vertices,
    faces)`` triple (V x 3 coordinates in the mesh's units, F x 3 vertex indices: an Open3D or
    trimesh mesh's arrays); or a dict ``{name: path or (vertices, faces)}``. Or ``manifest``: a
    manifest file (source, path, name per line) instead.

    ``params``: build parameters by the names of :attr:`Database.settings` (``"scan.fine_spacing"``,
    ``"fpfh.feature_radius"``, ``"descriptor"``, ...); ``scale``: ``"fit"`` (every object scaled to
    ``max_extent``) or ``"keep"`` (each mesh's own size, in ``units``: m, cm, mm or in). The same
    inputs, parameters and seed give the same file for any thread count.

    ``progress(done, total, seconds_left)`` is called after each object. An exception it raises
    stops the build: the objects finished stay in ``out + ".parts"``, so the same call resumes,
    and the exception is raised again. The returned database's ``build_report`` holds what the
    build said (objects, warnings, congruent classes, times)."""
    out = os.fspath(out)
    if (meshes is None) == (manifest is None):
        raise _error("give meshes or manifest (one of them)", out, "meshes")
    inputs: List[Any] = []
    folder = ""
    arrays: Dict[str, str] = {}      # temporary mesh file -> what the caller gave
    with tempfile.TemporaryDirectory(prefix="touchstone-meshes-") as tmp:
        if manifest is None and isinstance(meshes, (str, os.PathLike)):
            folder = os.fspath(meshes)
        elif manifest is None:
            items = list(meshes.items()) if isinstance(meshes, Mapping) else list(meshes)
            for k, item in enumerate(items):
                if isinstance(meshes, Mapping):
                    name, value = item
                    item = (name, value) if isinstance(value, (str, os.PathLike)) else (name, *value)
                if isinstance(item, (str, os.PathLike)):
                    inputs.append(("", os.fspath(item), ""))
                elif not isinstance(item, (tuple, list)):
                    raise _error("expected a path, (name, path) or (name, vertices, faces)", out, f"meshes[{k}]")
                elif len(item) == 2:
                    inputs.append((str(item[0]), os.fspath(item[1]), ""))
                elif len(item) == 3:
                    name = str(item[0])
                    path = os.path.join(tmp, f"{k:06d}.off")
                    _write_off(path, item[1], item[2], name, out, f"meshes[{k}]")
                    arrays[path] = f"meshes[{k}]"
                    inputs.append((name, path, "python arrays"))
                else:
                    raise _error("expected a path, (name, path) or (name, vertices, faces)", out, f"meshes[{k}]")
        try:
            report = _ts.build_database_impl(out, inputs, os.fspath(manifest or ""), folder,
                                             dict(params or {}), scale, units, seed, congruence_tolerance,
                                             threads, progress)
        except Error as e:
            # An error about arrays names the item, not the temporary file it was written to.
            file = getattr(e, "file", "")
            if file in arrays:
                raise _error(e.message.replace(file, arrays[file]), out, arrays[file]) from None
            raise
    db = Database(out)
    db.build_report = report
    return db


def report(store: str) -> Dict[str, Any]:
    """The report of a run store (``touchstone report --json``)."""
    return json.loads(_ts.report_json(store))


def read_runs(path: str) -> Dict[str, Any]:
    """A run store as NumPy arrays: ``header`` (configuration JSON, objects, stages, ...),
    ``runs`` (per run: variant, object, run, truth 4 x 4, wall time) and ``steps`` (runs x steps
    per column: best_object, correct, weight, posteriors, errors, pose runs x steps x 4 x 4,
    stage_times_s and values runs x steps x columns)."""
    return _ts.read_runs(path)
