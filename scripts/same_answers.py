#!/usr/bin/env python3
"""Check that two run stores answer identically, bit for bit: for every run both hold (same
variant label, explored object and run number), each step's best object, pose, weight,
posteriors, hypothesis count and every per-step value both stores name (times excepted).

  scripts/same_answers.py A.h5 B.h5      (a store, or a store's A.h5.runs/ folder while it runs)

For a change that must not alter answers (a refactoring): run the same study file on the same
database with the commit before and after, then compare the stores. Prints what was compared and
each difference (the first few per field); exits 1 when any differs or when no run is common."""
import sys
from pathlib import Path

import h5py
import numpy as np

FIELDS = ("step", "correct", "best_object", "true_rank", "hypotheses", "contacts", "free_points", "weight",
          "posterior_true", "posterior_best", "posterior_entropy", "pose")


def load_file(path, runs):
    """Adds the runs of one store file to `runs`: key -> ({field: array}, {value name: array})."""
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        sys.exit(f"same_answers: error: {path}: not a run store ({e})")
    with f:
        for name in ("header/objects", "runs/object", "runs/run", "runs/first_step_row", "steps/step"):
            if name not in f:
                sys.exit(f"same_answers: error: {path}: no dataset /{name} (not a run store?)")
        objects = [o.decode() for o in f["header/objects"][()]]
        labels = [x.decode() if isinstance(x, bytes) else str(x) for x in f["header/variant_labels"][()]] \
            if "header/variant_labels" in f else [""]
        names = [x.decode() for x in f["header/step_values"][()]] if "header/step_values" in f else []
        r, s = f["runs"], f["steps"]
        variant = r["variant"][()] if "variant" in r else np.zeros(len(r["run"]), dtype=int)
        steps = {k: s[k][()] for k in FIELDS if k in s}
        vals = s["values"][()] if "values" in s else np.zeros((len(s["step"]), 0))
        first = r["first_step_row"][()]
        for i in range(len(r["run"])):
            a, b = int(first[i]), int(first[i + 1]) if i + 1 < len(first) else len(s["step"])
            key = (labels[int(variant[i])], objects[int(r["object"][i])], int(r["run"][i]))
            runs[key] = ({k: v[a:b] for k, v in steps.items()}, {n: vals[a:b, j] for j, n in enumerate(names)})


def load(path):
    """A store file, or a store's RUN.h5.runs/ folder of completed runs (a study still running)."""
    runs = {}
    p = Path(path)
    for f in sorted(p.glob("*.h5")) if p.is_dir() else [p]:
        load_file(f, runs)
    return runs


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    ra, rb = load(sys.argv[1]), load(sys.argv[2])
    common = sorted(set(ra) & set(rb))
    if not common:
        sys.exit("same_answers: error: the stores hold no run in common")
    differ, shown, steps, nvalues = {}, {}, 0, 0
    for key in common:
        (sa, va), (sb, vb) = ra[key], rb[key]
        if len(sa["step"]) != len(sb["step"]):
            differ["steps per run"] = differ.get("steps per run", 0) + 1
            continue
        steps += len(sa["step"])
        value_names = [n for n in va if n in vb]
        nvalues = max(nvalues, len(value_names))
        checks = [(k, sa[k], sb[k]) for k in FIELDS if k in sa and k in sb]
        checks += [(f"values/{n}", va[n], vb[n]) for n in value_names]
        for name, x, y in checks:
            if not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
                differ[name] = differ.get(name, 0) + 1
                if shown.get(name, 0) < 3:
                    shown[name] = shown.get(name, 0) + 1
                    print(f"  differs: {name} in run {key}")
    print(f"same_answers: {len(common)} runs in common ({len(ra)} in A, {len(rb)} in B), {steps} steps; "
          f"compared {len(FIELDS)} step fields and {nvalues} per-step values")
    if differ:
        for name, n in sorted(differ.items()):
            print(f"  {name}: {n} runs differ")
        return 1
    print("  identical")
    return 0


if __name__ == "__main__":
    sys.exit(main())
