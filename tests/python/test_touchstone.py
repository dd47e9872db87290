"""The touchstone Python module against the touchstone command and the library's own outputs.

Run by ctest (tests/CMakeLists.txt: PYTHONPATH=build/python, TS_BINARY_DIR=build); a small
catalogue database of four objects is built once per session by the command itself.
"""

import ast
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import touchstone as ts

BINARY_DIR = Path(os.environ.get("TS_BINARY_DIR", Path(__file__).resolve().parents[2] / "build"))
TOUCHSTONE = BINARY_DIR / "touchstone"
STUB = Path(ts.__file__).with_name("__init__.pyi")


def run(*args):
    p = subprocess.run([str(TOUCHSTONE), *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout


@pytest.fixture(scope="session")
def built(tmp_path_factory):
    root = tmp_path_factory.mktemp("db")
    run("catalogue", "--count", 4, "--seed", 1, "--out", root / "cat")
    run("db", "build", "--manifest", root / "cat" / "manifest.tsv", "--out", root / "db.h5", "--scale", "keep",
        "--threads", 2)
    names = [line.split("\t")[2] for line in (root / "cat" / "manifest.tsv").read_text().splitlines()
             if line and not line.startswith("#")]
    return root, names


@pytest.fixture(scope="session")
def db(built):
    return ts.Database(str(built[0] / "db.h5"))


class Enough(Exception):
    """What a progress callback raises to stop a long call."""


def stop_at(n):
    """A progress callback that raises Enough when `done` reaches n."""
    def progress(done, total, left):
        if done == n:
            raise Enough("stop here")
    return progress


def rotation_to_quaternion(R):
    """(w, x, y, z) with w >= 0, as the command's JSON writes poses: Eigen's conversion from a
    rotation matrix (the trace branch when the trace is positive, else the branch of the largest
    diagonal entry, so no component comes from the square root of a small difference), then
    normalized. A formula that takes every component from a square root loses about 1e-12 on a
    component near 0."""
    t = R[0, 0] + R[1, 1] + R[2, 2]
    q = np.zeros(4)  # w, x, y, z
    if t > 0.0:
        t = np.sqrt(t + 1.0)
        q[0] = 0.5 * t
        t = 0.5 / t
        q[1] = (R[2, 1] - R[1, 2]) * t
        q[2] = (R[0, 2] - R[2, 0]) * t
        q[3] = (R[1, 0] - R[0, 1]) * t
    else:
        i = 0
        if R[1, 1] > R[0, 0]:
            i = 1
        if R[2, 2] > R[i, i]:
            i = 2
        j, k = (i + 1) % 3, (i + 2) % 3
        t = np.sqrt(R[i, i] - R[j, j] - R[k, k] + 1.0)
        q[1 + i] = 0.5 * t
        t = 0.5 / t
        q[0] = (R[k, j] - R[j, k]) * t
        q[1 + j] = (R[j, i] + R[i, j]) * t
        q[1 + k] = (R[k, i] + R[i, k]) * t
    q /= np.linalg.norm(q)
    return -q if q[0] < 0.0 else q


def test_database_lists_the_manifest(built, db):
    _, names = built
    assert len(db) == 4
    assert db.objects == [n for n in names if n in db.objects] and sorted(db.objects) == sorted(names)
    for i, name in enumerate(db.objects):
        assert db.index(name) == i
        info = db.object_info(name)
        assert info["name"] == name and info["index"] == i
        assert info["extent_m"].shape == (3,) and np.all(info["extent_m"] > 0.005)
        assert info["fine_points"] > info["coarse_points"] > 0
        assert db.object_info(i)["name"] == name
    assert db.settings["descriptor"] == "fpfh" and db.settings["fpfh.feature_radius"] > 0
    with pytest.raises(ts.Error) as e:
        db.index("no_such_object")
    assert "no_such_object" in str(e.value) and e.value.field == "object"
    with pytest.raises(IndexError):
        db.object_info(4)


def read_ascii_ply(path):
    """(points N x 3, normals N x 3) of an ascii PLY with x y z nx ny nz vertices."""
    lines = Path(path).read_text().splitlines()
    end = lines.index("end_header")
    n = int(next(l.split()[2] for l in lines[:end] if l.startswith("element vertex")))
    rows = np.array([[float(x) for x in l.split()] for l in lines[end + 1:end + 1 + n]])
    return rows[:, :3], rows[:, 3:6]


def test_geometry_arrays_are_the_databases(built, db, tmp_path):
    """points/normals equal what `db export --ascii` writes; the mesh spans the object's extent;
    the distance field is 0 on the surface points and d at points moved d out along their normals."""
    name = db.objects[0]
    info = db.object_info(name)
    for cloud, count in (("fine", info["fine_points"]), ("coarse", info["coarse_points"])):
        p, n = db.points(name, cloud), db.normals(name, cloud)
        assert p.shape == (count, 3) and n.shape == (count, 3)
        run("db", "export", built[0] / "db.h5", "--object", name, "--cloud", cloud, "--ascii",
            "--out", tmp_path / (cloud + ".ply"))
        ep, en = read_ascii_ply(tmp_path / (cloud + ".ply"))
        np.testing.assert_allclose(p, ep, rtol=0, atol=1e-6)   # ascii keeps 6-7 significant digits
        np.testing.assert_allclose(n, en, rtol=0, atol=1e-5)
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)
    assert np.array_equal(db.points(0), db.points(name))
    vertices, faces = db.mesh(name)
    assert vertices.shape[1] == 3 and faces.shape[1] == 3 and faces.dtype == np.int64
    assert faces.min() == 0 and faces.max() < len(vertices)
    np.testing.assert_allclose(vertices.max(0) - vertices.min(0), info["extent_m"], rtol=1e-9, atol=1e-9)
    # Surface points: 0 within the field's interpolation (a fraction of its voxel); moved out
    # along their normals by d (inside its fine band): d within a fraction of a voxel.
    p, n = db.points(name), db.normals(name)
    voxel = db.settings["field.fine_voxel"]
    sample = p[:: max(1, len(p) // 400)], n[:: max(1, len(p) // 400)]
    assert np.max(np.abs(db.distance(name, sample[0]))) < 0.5 * voxel
    d = 0.5 * db.settings["field.fine_band_voxels"] * voxel   # within the fine band
    out = db.distance(name, sample[0] + d * sample[1])
    assert np.median(np.abs(out - d)) < 0.25 * voxel
    assert db.distance(name, np.zeros((0, 3))).shape == (0,)
    with pytest.raises(ValueError):
        db.points(name, "medium")
    with pytest.raises(ValueError):
        db.distance(name, np.zeros((4, 2)))


def test_build_database_is_the_commands(built, tmp_path):
    """build_database from the manifest writes the very file `db build` wrote (same seed, any
    thread count), and its report names the objects."""
    root, names = built
    db = ts.build_database(str(tmp_path / "py.h5"), manifest=str(root / "cat" / "manifest.tsv"), scale="keep",
                           threads=1)
    assert db.objects == names and db.build_report["objects"] == names
    assert db.build_report["resumed"] == 0 and db.build_report["times_s"]["wall"] > 0
    assert (tmp_path / "py.h5").read_bytes() == (root / "db.h5").read_bytes()
    assert not (tmp_path / "py.h5.parts").exists()


def test_build_database_from_arrays(db, tmp_path):
    """(name, vertices, faces) arrays: the object's mesh is those arrays (centred, metres), and
    its scanned points lie on the original object's surface."""
    name = db.objects[1]
    vertices, faces = db.mesh(name)
    shifted = vertices + np.array([0.5, -2.0, 3.0])          # the object frame centres it again
    new = ts.build_database(str(tmp_path / "arr.h5"), [(name, shifted, faces)], scale="keep")
    assert new.objects == [name]
    v, f = new.mesh(name)
    assert np.array_equal(f, faces)
    np.testing.assert_allclose(v, vertices, rtol=0, atol=1e-6)
    voxel = db.settings["field.fine_voxel"]
    on = db.distance(name, new.points(name))
    assert np.max(np.abs(on)) < 0.5 * voxel
    assert new.object_info(name)["source"] == "python arrays"
    # {name: (vertices, faces)} and {name: path} name the objects as given.
    mesh_file = tmp_path / "m.off"
    with open(mesh_file, "w") as out:
        out.write(f"OFF\n{len(vertices)} {len(faces)} 0\n")
        np.savetxt(out, vertices, fmt="%.17g")
        np.savetxt(out, np.hstack([np.full((len(faces), 1), 3), faces]), fmt="%d")
    two = ts.build_database(str(tmp_path / "two.h5"), {"first": (vertices, faces), "second": str(mesh_file)},
                            scale="keep")
    assert two.objects == ["first", "second"]
    np.testing.assert_allclose(two.mesh("second")[0], vertices, rtol=0, atol=1e-6)


def test_build_database_progress_and_resume(built, tmp_path):
    """progress(done, total, seconds_left) after each object; what it raises stops the build with
    the finished objects kept, and the same call resumes to the same file."""
    root, names = built
    cat = root / "cat" / "meshes"
    meshes = sorted(p for p in cat.iterdir() if p.is_file())[:3]
    calls = []
    ts.build_database(str(tmp_path / "full.h5"), [str(p) for p in meshes], scale="keep", threads=1,
                      progress=lambda done, total, left: calls.append((done, total, left)))
    assert [c[:2] for c in calls] == [(1, 3), (2, 3), (3, 3)]
    assert all(left >= 0 for _, _, left in calls) and calls[-1][2] == 0
    out = tmp_path / "stopped.h5"
    with pytest.raises(Enough):
        ts.build_database(str(out), [str(p) for p in meshes], scale="keep", threads=1, progress=stop_at(1))
    assert not out.exists() and (tmp_path / "stopped.h5.parts").is_dir()
    seen = []
    resumed = ts.build_database(str(out), [str(p) for p in meshes], scale="keep", threads=1,
                                progress=lambda done, total, left: seen.append(done))
    assert seen == [2, 3] and resumed.build_report["resumed"] == 1
    assert out.read_bytes() == (tmp_path / "full.h5").read_bytes()
    # Two threads: the callback runs on a worker thread (taking the GIL there); what it raises
    # still stops the build, and the same call resumes to the same bytes.
    out2 = tmp_path / "stopped2.h5"
    with pytest.raises(Enough):
        ts.build_database(str(out2), [str(p) for p in meshes], scale="keep", threads=2, progress=stop_at(1))
    assert not out2.exists()
    again = ts.build_database(str(out2), [str(p) for p in meshes], scale="keep", threads=2)
    assert again.build_report["resumed"] >= 1
    assert out2.read_bytes() == (tmp_path / "full.h5").read_bytes()


def test_build_database_rejects_bad_input(db, tmp_path):
    vertices, faces = db.mesh(0)
    out = str(tmp_path / "bad.h5")
    cases = [({"params": {"scan.bogus": 1}}, "scan.bogus"),
             ({"params": {"scan.fine_spacing": -0.001}}, "scan.fine_spacing"),
             ({"params": {"scan.max_views": 2.5}}, "scan.max_views"),
             ({"params": {"descriptor": "sift"}}, "descriptor"),
             ({"scale": "stretch"}, "scale"),
             ({"units": "furlong"}, "units")]
    for kwargs, field in cases:
        with pytest.raises(ts.Error) as e:
            ts.build_database(out, [("x", vertices, faces)], **kwargs)
        assert e.value.field == field and e.value.file == out, (kwargs, e.value)
    # Arrays the wrapper refuses, and a mesh the importer refuses (all faces degenerate): the
    # item is named, never the temporary file it would be written to.
    flat = np.zeros_like(vertices)
    for bad in ((vertices[:, :2], faces), (vertices, faces + len(vertices)), (vertices * np.nan, faces), (flat, faces)):
        with pytest.raises(ts.Error) as e:
            ts.build_database(out, [("y", vertices, faces), ("x", *bad)])
        assert e.value.file == out and e.value.field == "meshes[1]", e.value
        assert "touchstone-meshes-" not in str(e.value), e.value
    with pytest.raises(ts.Error) as e:
        ts.build_database(out, [("bad name/", vertices, faces)])
    assert e.value.field == "meshes[0]", e.value
    with pytest.raises(ts.Error) as e:
        ts.build_database(out, [("x", vertices, faces)], params={"scan.max_views": True})
    assert e.value.field == "scan.max_views", e.value
    with pytest.raises(ts.Error) as e:
        ts.build_database(out)                                  # neither meshes nor manifest
    assert e.value.field == "meshes"
    assert ts.build_database(str(tmp_path / "np.h5"), [("x", vertices, faces)],
                             params={"scan.max_views": np.int64(40), "scan.coarse_voxel": np.float32(0.006)}
                             ).settings["scan.max_views"] == 40
    with pytest.raises(TypeError):
        ts.build_database(out, [("x", vertices, faces)], progress=3)
    assert not os.path.exists(out) and not os.path.exists(out + ".parts")


def test_open3d_example_round_trip(tmp_path):
    """examples/python/open3d_roundtrip.py: Open3D meshes -> a database, an Open3D cloud -> the
    answer, which names the touched primitive and lies on its contacts."""
    pytest.importorskip("open3d")   # scripts/setup installs python3-open3d
    script = Path(__file__).resolve().parents[2] / "examples" / "python" / "open3d_roundtrip.py"
    for touched in ("cylinder", "torus"):
        p = subprocess.run([sys.executable, str(script), str(tmp_path / touched), touched], capture_output=True,
                           text=True, env={**os.environ})
        assert p.returncode == 0, p.stderr
        assert f"answer {touched} " in p.stdout and "right" in p.stdout, p.stdout
        median = float(p.stdout.split("median ")[1].split(" mm")[0])
        assert median < 3.0, p.stdout                         # underwater noise: 3 mm arm error
        assert (tmp_path / touched / "answer.ply").stat().st_size > 0


def test_errors_name_the_file(tmp_path):
    missing = tmp_path / "missing.h5"
    with pytest.raises(ts.Error) as e:
        ts.Database(str(missing))
    assert e.value.file == str(missing) and str(missing) in str(e.value)
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not an HDF5 file" * 8)
    with pytest.raises(ts.Error) as e:
        ts.read_log(str(bad))
    assert e.value.file == str(bad)


def test_simulate_writes_what_the_command_writes(built, db, tmp_path):
    root, names = built
    log = ts.simulate(db, names[0], grasps=6, noise="underwater", sensors=1, seed=3)
    assert len(log) == 6 and log.object == names[0] and log.noise == "underwater" and log.pads == 1
    log.write(str(tmp_path / "py.h5"))
    run("simulate", "--db", root / "db.h5", "--object", names[0], "--grasps", 6, "--noise", "underwater",
        "--sensors", 1, "--seed", 3, "--out", tmp_path / "cli.h5")
    a, b = ts.read_log(str(tmp_path / "py.h5")), ts.read_log(str(tmp_path / "cli.h5"))
    assert np.array_equal(a.arm_poses(), b.arm_poses())
    assert np.array_equal(a.truth_pose, b.truth_pose) and a.truth_pose.shape == (4, 4)
    with pytest.raises(ts.Error):
        ts.simulate(db, names[0], params={"ransac.object_draws": 5})   # a method parameter


def test_recognize_log_returns_what_the_command_returns(built, db, tmp_path):
    root, names = built
    log = ts.simulate(db, names[1], grasps=8, seed=5)
    path = tmp_path / "log.h5"
    log.write(str(path))
    cli = json.loads(run("recognize", "--db", root / "db.h5", "--log", path, "--json", "--seed", 2,
                         "--threads", 2))
    steps = ts.Recognizer(db, seed=2).recognize_log(ts.read_log(str(path)))
    assert len(steps) == len(cli["steps"]) == 8
    for py, c in zip(steps, cli["steps"]):
        assert py.step == c["step"] and py.object == c["object"]
        assert py.log_weight == c["log_weight"] and py.posterior == c["posterior"]
        assert py.contacts == c["contacts"] and py.free_points == c["free_points"]
        assert py.valid == (c["pose"] is not None)
        if not py.valid:
            continue
        assert np.array_equal(py.pose[:3, 3], np.array(c["pose"]["t"]))
        np.testing.assert_allclose(rotation_to_quaternion(py.pose[:3, :3]), c["pose"]["q"], rtol=0, atol=1e-12)
        assert py.correct == c["correct"]
        assert py.position_error_m == c["position_error_m"]
    last = steps[-1]
    assert last.valid and last.hypotheses[0].object == last.object
    assert np.array_equal(last.hypotheses[0].pose, last.pose)
    assert last.posteriors.shape == (4,) and abs(last.posteriors.sum() - 1.0) < 1e-9
    assert last.posterior == pytest.approx(last.posteriors[last.object_index], rel=1e-12)


def test_attribution_is_the_commands(built, db, tmp_path):
    root, names = built
    log = ts.simulate(db, names[1], grasps=8, seed=5)
    path = tmp_path / "log.h5"
    log.write(str(path))
    cli = json.loads(run("recognize", "--db", root / "db.h5", "--log", path, "--json", "--seed", 2,
                         "--threads", 1, "--outlier", 0.015))
    plain = ts.Recognizer(db, seed=2).recognize_log(ts.read_log(str(path)))
    steps = ts.Recognizer(db, seed=2, params={"evaluate.outlier_m": 0.015}).recognize_log(ts.read_log(str(path)))
    assert all(p.attribution is None for p in plain)
    for py, c in zip(steps, cli["steps"]):
        assert py.object == c["object"]
        labels = "".join("osu"[x] for x in py.attribution)
        assert labels == c["attribution"]["labels"] and len(labels) == py.contacts
    last = steps[-1]
    assert last.correct
    assert (last.attribution == 0).mean() > 0.95   # no scene: the right answer explains its contacts


def test_support_is_the_commands(built, db, tmp_path):
    # The object on a pipe: support.mode = cylinder finds it in Python as the command does.
    root, names = built
    log = ts.simulate(db, names[1], grasps=20, noise="ideal", seed=5,
                      params={"scene": "pipe", "scene.pipe_radius_m": 0.08, "scene.off_target": 0.4})
    path = tmp_path / "pipe.h5"
    log.write(str(path))
    cli = json.loads(run("recognize", "--db", root / "db.h5", "--log", path, "--json", "--seed", 2,
                         "--support", "cylinder"))
    steps = ts.Recognizer(db, seed=2, params={"support.mode": "cylinder"}).recognize_log(ts.read_log(str(path)))
    found = 0
    for py, c in zip(steps, cli["steps"]):
        assert (py.support is None) == (c["support"] is None)
        assert py.support_verdict == c["support_verdict"]
        if py.support is None:
            continue
        found += 1
        assert py.support["shape"] == c["support"]["shape"] == "cylinder"
        np.testing.assert_array_equal(py.support["axis"], c["support"]["axis"])
        np.testing.assert_array_equal(py.support["point"], c["support"]["point"])
        assert py.support["radius_m"] == c["support"]["radius_m"]
        assert py.support["contacts"] == c["support"]["contacts"]
    assert found > 0
    assert abs(steps[-1].support["radius_m"] - 0.08) < 0.002


def test_explain_is_the_commands_and_changes_no_answer(built, db, tmp_path):
    root, names = built
    log = ts.simulate(db, names[1], grasps=6, seed=5)
    path = tmp_path / "log.h5"
    log.write(str(path))
    cli = json.loads(run("recognize", "--db", root / "db.h5", "--log", path, "--json", "--seed", 2,
                         "--threads", 1, "--explain"))
    plain = ts.Recognizer(db, seed=2).recognize_log(ts.read_log(str(path)))
    explained = ts.Recognizer(db, seed=2, explain=True).recognize_log(ts.read_log(str(path)))
    assert all(p.explanation is None for p in plain)
    for p, e, c in zip(plain, explained, cli["steps"]):
        assert (p.object, p.log_weight, p.posterior) == (e.object, e.log_weight, e.posterior)
        if not e.valid:
            continue
        x, cx = e.explanation, c["explanation"]
        assert x["decided_by"] == cx["decided_by"]
        assert [h["object"] for h in x["hypotheses"]] == [h["object"] for h in cx["hypotheses"]]
        for h, ch in zip(x["hypotheses"], cx["hypotheses"]):
            for key in ("log_weight", "contact_log_weight", "free_log_weight", "floor_log_weight", "rank", "posterior"):
                assert h[key] == ch[key], key
        assert x["hypotheses"][0]["role"] == "answer" and x["hypotheses"][0]["object"] == e.object
        assert x["hypotheses"][0]["log_weight"] == e.log_weight


def test_stepping_with_arrays_equals_recognize_log(db, built):
    _, names = built
    log = ts.simulate(db, names[2], grasps=5, seed=7)
    expected = ts.Recognizer(db, seed=4).recognize_log(log)
    rec = ts.Recognizer(db, seed=4)
    ex = ts.Exploration(log, db)
    for k, want in enumerate(expected, start=1):
        ex.advance_to(k)
        assert ex.steps == k
        got = rec.step(ex.contacts(), ex.free(), ex.grasps())
        assert sum(len(g) for g in ex.grasps()) >= len(ex.contacts()) > 0
        assert got.object == want.object and got.log_weight == want.log_weight
        assert np.array_equal(got.pose, want.pose)
        assert got.correct is None and want.correct is not None   # no truth given to step()
    assert [h.object for h in rec.hypotheses] == [h.object for h in expected[-1].hypotheses]
    rec.reset()
    assert rec.hypotheses == []


def test_stepping_with_the_hands_free_points_equals_recognize_log_on_the_seabed(db, built):
    # The support stage and the near-twin verification read the points each grasp's hand held
    # free and the arm error's pivots: with hand_free() and pivots() passed, step() is
    # recognize_log() on a seabed log with support.mode = plane, support verdicts included.
    _, names = built
    log = ts.simulate(db, names[0], grasps=12, seed=5,   # without hand_free, 7 of its 12 steps differ
                      params={"scene": "seabed", "scene.off_target": 0.4})
    params = {"support.mode": "plane"}
    expected = ts.Recognizer(db, seed=2, params=params).recognize_log(log)
    assert any(s.support is not None for s in expected)   # the seabed found at some step
    rec = ts.Recognizer(db, seed=2, params=params)
    ex = ts.Exploration(log, db)
    for k, want in enumerate(expected, start=1):
        ex.advance_to(k)
        grasps, hand_free, pivots = ex.grasps(), ex.hand_free(), ex.pivots()
        assert len(hand_free) == len(grasps) == pivots.shape[0] == k
        assert all(h.shape[1] == 3 and len(h) > 0 for h in hand_free)
        got = rec.step(ex.contacts(), ex.free(), grasps, hand_free=hand_free, pivots=pivots)
        assert got.support_verdict == want.support_verdict
        assert got.object == want.object and got.log_weight == want.log_weight
        assert np.array_equal(got.pose, want.pose)


def test_thread_count_changes_no_answer(db, built):
    _, names = built
    log = ts.simulate(db, names[3], grasps=5, seed=9)
    try:
        ts.set_threads(1)
        one = ts.Recognizer(db, seed=3).recognize_log(log)
        ts.set_threads(2)
        two = ts.Recognizer(db, seed=3).recognize_log(log)
    finally:
        ts.set_threads(0)
    assert [(s.object, s.log_weight) for s in one] == [(s.object, s.log_weight) for s in two]
    assert all(np.array_equal(a.pose, b.pose) for a, b in zip(one, two) if a.valid)
    # The step's pipeline: the same stages for any thread count; the first step has no survivors.
    assert [(s.stages_ran, s.stages_skipped) for s in one] == [(s.stages_ran, s.stages_skipped) for s in two]
    assert {"stage": "survivors", "reason": "no hypotheses from an earlier step"} in one[0].stages_skipped
    assert "survivors" in one[1].stages_ran and "scene" in one[0].stages_ran
    assert all(s.times_s["stage." + n] >= 0.0 for s in one for n in s.stages_ran)


def test_recognizers_in_python_threads(db, built):
    """Two recognizers in two Python threads (the GIL released in the long calls) give what
    each gives alone."""
    _, names = built
    logs = [ts.simulate(db, names[i], grasps=4, seed=11) for i in (0, 1)]
    alone = [ts.Recognizer(db, seed=1).recognize_log(log) for log in logs]
    together = [None, None]

    def work(i):
        together[i] = ts.Recognizer(db, seed=1).recognize_log(logs[i])

    threads = [threading.Thread(target=work, args=(i,)) for i in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for a, b in zip(alone, together):
        assert [(s.object, s.log_weight) for s in a] == [(s.object, s.log_weight) for s in b]


def test_parameters_and_settings(db):
    keys = {p["key"]: p for p in ts.parameters()}
    assert "ransac.object_draws" in keys and keys["ransac.object_draws"]["kind"] == "method"
    assert all(p["kind"] == "simulator" for p in ts.parameters("simulator"))
    rec = ts.Recognizer(db, params={"ransac.object_draws": 60, "twins.rivals": 3})
    assert rec.settings["ransac.object_draws"] == 60 and rec.settings["twins.rivals"] == 3
    default = ts.Recognizer(db).settings
    assert default["ransac.object_draws"] == keys["ransac.object_draws"]["default"]["improved"]
    with pytest.raises(ts.Error) as e:
        ts.Recognizer(db, params={"ransac.no_such_key": 1})
    assert e.value.field == "ransac.no_such_key"
    with pytest.raises(ts.Error) as e:
        ts.Recognizer(db, params={"ransac.object_draws": -4})   # out of range
    assert e.value.field == "ransac.object_draws"
    with pytest.raises(ts.Error):
        ts.Recognizer(db, params={"noise": "deepsea"})           # a simulator parameter
    with pytest.raises(ts.Error):
        ts.Recognizer(db, method="no-such-method")


def test_step_rejects_bad_arrays(db):
    rec = ts.Recognizer(db)
    with pytest.raises(ValueError):
        rec.step(np.zeros((5, 2)))
    with pytest.raises(ValueError):
        rec.step(np.array([[0.0, 0.0, np.nan]]))
    with pytest.raises(ValueError):
        rec.step(np.zeros((4, 3)), free=np.zeros(3))
    two = [np.zeros((2, 3)), np.ones((2, 3))]
    with pytest.raises(ValueError, match="hand_free: 1 entries for 2 grasps"):
        rec.step(np.zeros((4, 3)), grasps=two, hand_free=[np.zeros((3, 3))])
    with pytest.raises(ValueError, match="pivots: 3 rows for 2 grasps"):
        rec.step(np.zeros((4, 3)), grasps=two, pivots=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="give grasps too"):
        rec.step(np.zeros((4, 3)), hand_free=[np.zeros((3, 3))])


def test_only_limits_the_answer(db, built):
    _, names = built
    log = ts.simulate(db, names[1], grasps=6, seed=13)
    steps = ts.Recognizer(db, only=[names[1]]).recognize_log(log)   # localize a known object
    assert all(s.object in (None, names[1]) for s in steps) and steps[-1].valid
    limited = ts.Recognizer(db, only=[names[0], names[2], names[3]]).recognize_log(log)
    assert all(s.object != names[1] for s in limited)
    assert all(h.object != names[1] for s in limited for h in s.hypotheses)


def test_experiment_and_its_run_store(built, tmp_path):
    root, names = built
    out = tmp_path / "runs.h5"
    report = ts.run_experiment(str(root / "db.h5"), str(out),
                               set={"objects": names[:2], "runs": 2, "steps": 3, "seed": 4}, threads=2)
    runs = ts.read_runs(str(out))
    h = runs["header"]
    assert h["complete"] and h["steps"] == 3 and h["objects"] == names[:2]
    assert runs["steps"]["correct"].shape == (4, 3) and runs["steps"]["pose"].shape == (4, 3, 4, 4)
    assert runs["steps"]["stage_times_s"].shape == (4, 3, len(h["stages"]))
    assert sorted(zip(runs["runs"]["object"], runs["runs"]["run"])) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    # The report's recognition per step is the share of correct runs the arrays hold.
    for k, row in enumerate(report["per_step"]):
        assert row["recognition_rate"] == pytest.approx(runs["steps"]["correct"][:, k].mean(), abs=1e-12)
    names_of = h["database_objects"]
    best = runs["steps"]["best_object"]
    correct = np.array([[b >= 0 and names_of[b] == h["objects"][o] for b in row]
                        for row, o in zip(best, runs["runs"]["object"])])
    assert np.array_equal(correct, runs["steps"]["correct"])
    assert ts.report(str(out))["per_step"] == report["per_step"]
    with pytest.raises(ts.Error) as e:   # never silently overwritten
        ts.run_experiment(str(root / "db.h5"), str(out), set={"objects": names[:2], "runs": 2, "steps": 3})
    assert e.value.file == str(out)
    with pytest.raises(ts.Error) as e:
        ts.run_experiment(str(root / "db.h5"), str(tmp_path / "x.h5"), set={"runs": "many"})
    assert e.value.field == "runs"


def test_experiment_progress_callback(built, tmp_path):
    """progress(done, total, seconds_left) after each run; what it raises stops the experiment with
    the runs finished stored, and resume=True then completes the same report."""
    root, names = built
    config = {"objects": names[:2], "runs": 2, "steps": 2, "seed": 5}
    calls = []
    full = ts.run_experiment(str(root / "db.h5"), str(tmp_path / "a.h5"), set=config, threads=1,
                             progress=lambda done, total, left: calls.append((done, total, left)))
    assert [c[:2] for c in calls] == [(k, 4) for k in range(1, 5)]
    assert all(left is None or left >= 0 for _, _, left in calls)
    out = tmp_path / "b.h5"
    with pytest.raises(Enough):
        ts.run_experiment(str(root / "db.h5"), str(out), set=config, threads=1, progress=stop_at(2))
    seen = []
    resumed = ts.run_experiment(str(root / "db.h5"), str(out), set=config, threads=1, resume=True,
                                progress=lambda done, total, left: seen.append(done))
    assert seen == [3, 4]                           # two runs were kept; only the two others ran
    def answers(report):   # what the runs answered (their times differ from run to run)
        return [{k: v for k, v in row.items() if "time" not in k} for row in report["per_step"]]
    assert answers(resumed) == answers(full)
    with pytest.raises(TypeError):
        ts.run_experiment(str(root / "db.h5"), str(tmp_path / "c.h5"), set=config, progress=3)
    assert not (tmp_path / "c.h5").exists()


def test_set_answers_are_the_commands(built, db, tmp_path):
    """A calibration with answer sets: the Recognizer's answer_set is the command's, step by step."""
    root, names = built
    store = tmp_path / "cal.h5"
    ts.run_experiment(str(root / "db.h5"), str(store),
                      set={"objects": names, "runs": 3, "steps": 3, "seed": 6}, threads=2)
    run("calibrate", store, "--step-ranges", "1,3", "--alpha", "0.4", "--out", tmp_path / "cal.json")
    log = ts.simulate(db, names[2], grasps=3, seed=8)
    path = tmp_path / "log.h5"
    log.write(str(path))
    cli = json.loads(run("recognize", "--db", root / "db.h5", "--log", path, "--json", "--seed", 2,
                         "--calibration", tmp_path / "cal.json"))
    steps = ts.Recognizer(db, seed=2, calibration=str(tmp_path / "cal.json")).recognize_log(ts.read_log(str(path)))
    assert [s.answer_set for s in steps] == [c["answer_set"] for c in cli["steps"]]
    assert all(s.answer_set["alpha"] == 0.4 for s in steps)
    assert ts.Recognizer(db, seed=2).recognize_log(ts.read_log(str(path)))[0].answer_set is None
    with pytest.raises(ts.Error) as e:   # alpha without a calibration
        ts.Recognizer(db, alpha=0.1)
    assert e.value.field == "alpha"
    with pytest.raises(ts.Error) as e:
        ts.Recognizer(db, calibration=str(tmp_path / "cal.json"), alpha=1.5)
    assert e.value.field == "alpha"


def test_every_public_name_has_a_stub():
    tree = ast.parse(STUB.read_text())
    stubbed = {n.name for n in tree.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    stubbed |= {n.target.id for n in tree.body if isinstance(n, ast.AnnAssign)}
    missing = [name for name in ts.__all__ if name not in stubbed]
    assert not missing, missing
    classes = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef)}
    for name in ("Database", "TactileLog", "Exploration", "Recognizer"):
        public = {a for a in dir(getattr(ts, name)) if not a.startswith("_")} | (
            {"__len__"} if hasattr(getattr(ts, name), "__len__") else set())
        members = {f.name for f in classes[name].body if isinstance(f, ast.FunctionDef)}
        assert public <= members, (name, public - members)
