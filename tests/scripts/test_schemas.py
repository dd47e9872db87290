#!/usr/bin/env python3
"""Every `--json` output validates against its JSON Schema (docs/schemas/<command>.schema.json).

Builds a small database of three generated meshes, then runs each command that prints JSON on it
(simulate, recognize, an experiment in two shards, merge, report, calibrate, ...) and validates
the one object each prints on stdout against the command's schema. Also checks that the schemas
themselves are valid (Draft 2020-12), that every schema file is used, and that a schema rejects
an output whose required key is removed (the test can fail).

    python3 tests/scripts/test_schemas.py build/touchstone . [DUMP_DIR]
"""
import json
import pathlib
import subprocess
import sys
import tempfile

import jsonschema

# Coarse database parameters: the outputs' shape is checked, not their accuracy.
FAST_DB = ["--fine-spacing", "0.006", "--coarse-voxel", "0.02", "--max-views", "24", "--normal-radius", "0.015",
           "--feature-radius", "0.03", "--field-voxel", "0.01", "--field-band", "2", "--field-coarse-voxel", "0.04",
           "--field-margin", "0.04"]
FAST_RECOGNIZE = ["-N", "6", "-R", "40", "-W", "800", "--n-p", "20", "--icp-points", "64"]
FAST_EXPERIMENT = ["--runs", "2", "--steps", "3", "--pool", "4", "--set", "ransac.triplets=6",
                   "--set", "ransac.registrations=40", "--set", "ransac.prune=800", "--set", "bricpsf.hypotheses=20",
                   "--set", "icp.points=64"]


def write_off(path, vertices, faces):
    with open(path, "w") as f:
        f.write("OFF\n%d %d 0\n" % (len(vertices), len(faces)))
        for v in vertices:
            f.write("%g %g %g\n" % tuple(v))
        for t in faces:
            f.write("3 %d %d %d\n" % tuple(t))


def box(sx, sy, sz):
    v = [(x * sx, y * sy, z * sz) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    # Outward triangles of the six faces (vertex index = 4x + 2y + z).
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = []
    for a, b, c, d in quads:
        faces += [(a, b, c), (a, c, d)]
    return v, faces


def wedge(sx, sy, sz):
    """A triangular prism: the triangle (0,0) (sx,0) (0,sy) swept along z."""
    v = [(0, 0, 0), (sx, 0, 0), (0, sy, 0), (0, 0, sz), (sx, 0, sz), (0, sy, sz)]
    faces = [(0, 2, 1), (3, 4, 5), (0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4), (2, 0, 3), (2, 3, 5)]
    return v, faces


class Runner:
    def __init__(self, touchstone, cwd):
        self.touchstone = touchstone
        self.cwd = cwd

    def json(self, *args):
        r = subprocess.run([self.touchstone, *args, "--json"], cwd=self.cwd, capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit("touchstone %s failed (%d): %s" % (" ".join(args), r.returncode, r.stderr))
        return json.loads(r.stdout)


def main():
    touchstone = str(pathlib.Path(sys.argv[1]).resolve())
    src = pathlib.Path(sys.argv[2]).resolve()
    dump = pathlib.Path(sys.argv[3]) if len(sys.argv) > 3 else None   # keep the outputs here
    schema_dir = src / "docs" / "schemas"
    schemas = {p.name[:-len(".schema.json")]: json.loads(p.read_text()) for p in schema_dir.glob("*.schema.json")}
    for name, schema in schemas.items():
        jsonschema.Draft202012Validator.check_schema(schema)
    outputs = {}
    with tempfile.TemporaryDirectory() as tmp:
        d = pathlib.Path(tmp)
        (d / "meshes").mkdir()
        write_off(d / "meshes" / "box.off", *box(0.08, 0.05, 0.03))
        write_off(d / "meshes" / "wedge.off", *wedge(0.07, 0.05, 0.04))
        write_off(d / "meshes" / "bar.off", *box(0.02, 0.02, 0.12))
        write_off(d / "extra.off", *box(0.06, 0.06, 0.06))
        t = Runner(touchstone, d)
        outputs["db-build"] = t.json("db", "build", "--meshes", "meshes", "--out", "db.h5", "--quiet", *FAST_DB)
        outputs["db-info"] = t.json("db", "info", "db.h5")
        outputs["db-classes"] = t.json("db", "classes", "db.h5")
        outputs["db-export"] = t.json("db", "export", "db.h5", "--object", "box", "--out", "box.ply")
        subprocess.run(["cp", "db.h5", "db4.h5"], cwd=d, check=True)
        outputs["db-add"] = t.json("db", "add", "db4.h5", "extra.off", "--name", "cube")
        outputs["simulate"] = t.json("simulate", "--db", "db.h5", "--object", "wedge", "--grasps", "4", "--seed", "2",
                                     "--out", "log.h5")
        outputs["log-info"] = t.json("log", "info", "log.h5")
        outputs["log-export"] = t.json("log", "export", "log.h5", "--out", "cloud.ply")
        outputs["recognize"] = t.json("recognize", "--db", "db.h5", "--log", "log.h5", "--explain", *FAST_RECOGNIZE)
        cloud = t.json("recognize", "--db", "db.h5", "--cloud", "cloud.ply", *FAST_RECOGNIZE)
        subprocess.run(["cp", "log.h5", "log2.h5"], cwd=d, check=True)
        several = t.json("recognize", "--db", "db.h5", "--log", "log.h5", "log2.h5", *FAST_RECOGNIZE)
        outputs["experiment"] = t.json("experiment", "--db", "db.h5", "--objects", "box,wedge", "--out", "e.h5",
                                       "--quiet", *FAST_EXPERIMENT)
        for i in (1, 2):
            t.json("experiment", "--db", "db.h5", "--objects", "box,wedge", "--out", "s%d.h5" % i, "--quiet",
                   "--shard", "%d/2" % i, *FAST_EXPERIMENT)
        outputs["merge"] = t.json("merge", "--out", "m.h5", "s1.h5", "s2.h5", "--quiet")
        outputs["report"] = t.json("report", "e.h5")
        outputs["calibrate"] = t.json("calibrate", "e.h5", "m.h5", "--out", "cal.json", "--step-ranges", "1,3", "--quiet")
        outputs["params"] = t.json("params")
        outputs["catalogue"] = t.json("catalogue", "--count", "2", "--out", "cat", "--quiet")
        outputs["stress"] = t.json("stress", "--config", str(src / "experiments/studies/stress/study10_extreme.toml"),
                                   "--cases", "contacts_3", "--runs", "1")
        mcap = src / "tests" / "fuzz" / "corpus" / "mcap" / "conformance-ten-messages-all-features.mcap"
        outputs["log-topics"] = t.json("log", "topics", str(mcap))
    if dump:
        dump.mkdir(parents=True, exist_ok=True)
        for name, output in outputs.items():
            (dump / (name + ".json")).write_text(json.dumps(output, indent=1))
        (dump / "recognize-cloud.json").write_text(json.dumps(cloud, indent=1))
        (dump / "recognize-several.json").write_text(json.dumps(several, indent=1))
    failures = []
    schemas["experiment"] = schemas.get("report")   # `experiment --json` prints its report
    for name, output in outputs.items():
        if name not in schemas:
            failures.append("no schema docs/schemas/%s.schema.json for `%s --json`" % (name, name.replace("-", " ")))
            continue
        errors = sorted(jsonschema.Draft202012Validator(schemas[name]).iter_errors(output), key=str)
        for e in errors[:5]:
            failures.append("%s: %s at %s" % (name, e.message, "/".join(map(str, e.absolute_path))))
    # A plain cloud's recognition is the same shape as a log's; several inputs give "inputs".
    for label, output in (("recognize --cloud", cloud), ("recognize (several inputs)", several)):
        for e in jsonschema.Draft202012Validator(schemas["recognize"]).iter_errors(output):
            failures.append("%s: %s at %s" % (label, e.message, "/".join(map(str, e.absolute_path))))
    if jsonschema.Draft202012Validator(schemas["recognize"]).is_valid({"database": "db.h5", "inputs": [{}]}):
        failures.append("recognize.schema.json accepts an input without its steps")
    # log import needs a ROS 2 recording (tests/experiments/test_tactile_cli.cpp writes one and
    # validates that output against log-import.schema.json).
    unused = sorted(set(schemas) - set(outputs) - {"log-import"})
    failures += ["schema %s.schema.json validates no output here" % n for n in unused]
    # The schemas can fail: each output without its first required key is rejected.
    for name, output in outputs.items():
        required = schemas.get(name, {}).get("required", [])
        if not required:
            failures.append("%s.schema.json requires no key" % name)
            continue
        cut = dict(output)
        cut.pop(required[0], None)
        if jsonschema.Draft202012Validator(schemas[name]).is_valid(cut):
            failures.append("%s.schema.json accepts the output without '%s'" % (name, required[0]))
    if failures:
        print("\n".join(failures))
        sys.exit(1)
    print("%d outputs validated against %d schemas" % (len(outputs) + 1, len(schemas)))


if __name__ == "__main__":
    main()
