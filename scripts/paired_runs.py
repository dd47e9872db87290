#!/usr/bin/env python3
"""Compare two run stores of the same runs, paired: the same explored objects, runs, object poses
and grasps (for example one database built with two descriptors, the same study file and seed).

    /usr/bin/python3 scripts/paired_runs.py rec_fpfh.h5 rec_spin.h5 [--steps 5,10,20]
    /usr/bin/python3 scripts/paired_runs.py s12.h5 s12.h5 --variant-a exploration.strategy=random \
        --variant-b exploration.strategy=active --grasps-may-differ [--objects bunny,pipe,...]

A store with a sweep holds several variants: --variant-a / --variant-b pick one by its label as
`touchstone report` prints it (a store of one variant needs none). Active exploration chooses
other grasps than the random runs it is paired with: --grasps-may-differ then checks the object
pose and the first grasp only.

--objects restricts both to the named explored objects (a subset chosen beforehand, e.g. the
worst of another study: choosing it on these runs would bias the comparison).

Per step: the share right in A and in B, runs right in both, in A only, in B only; McNemar's exact test on the discordant runs
(assumes every run independent: too optimistic when runs of one object share its geometry) and a
sign test over the explored objects (how many objects gain, how many lose; assumes only the
objects independent), and a 95 % bootstrap interval of the difference B - A in points that
resamples the explored objects with their runs (the runs of one object fail together). Refuses
stores whose runs differ in pose or grasps.
"""
import argparse
import sys
from math import comb

import h5py
import numpy as np


def two_sided_binomial(k, n):
    """P(X <= min(k, n - k)) * 2 for X ~ Binomial(n, 1/2), at most 1."""
    if n == 0:
        return 1.0
    m = min(k, n - k)
    return min(1.0, 2.0 * sum(comb(n, i) for i in range(m + 1)) / 2.0 ** n)


def load(path, variant, grasps_may_differ):
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        sys.exit(f"paired_runs: error: {path}: not a run store ({e})")
    with f:
        for name in ("runs/object", "runs/run", "runs/first_step_row", "runs/truth", "runs/grasps", "steps/correct"):
            if name not in f:
                sys.exit(f"paired_runs: error: {path}: no dataset /{name} (not a run store?)")
        r, s = f["runs"], f["steps"]
        objects = [o.decode() for o in f["header/objects"][()]]
        correct = s["correct"][()].astype(bool)
        labels = [x.decode() if isinstance(x, bytes) else str(x) for x in f["header/variant_labels"][()]] \
            if "header/variant_labels" in f else [""]
        if variant is None:
            if len(labels) > 1:
                sys.exit(f"paired_runs: error: {path}: {len(labels)} variants ({', '.join(labels)}): "
                         "name one with --variant-a / --variant-b")
            chosen = 0
        elif variant in labels:
            chosen = labels.index(variant)
        else:
            sys.exit(f"paired_runs: error: {path}: no variant {variant!r} (/header/variant_labels: {', '.join(labels)})")
        runs_variant = r["variant"][()] if "variant" in r else np.zeros(len(r["run"]), dtype=int)
        out = {}
        for i in range(len(r["run"])):
            if int(runs_variant[i]) != chosen:
                continue
            key = (objects[int(r["object"][i])], int(r["run"][i]))
            first = int(r["first_step_row"][i])
            steps = r["grasps"].shape[1]
            if first < 0 or first + steps > len(correct):
                sys.exit(f"paired_runs: error: {path}: /runs/first_step_row of run {i} out of range")
            grasps = r["grasps"][i][:1] if grasps_may_differ else r["grasps"][i]
            out[key] = (correct[first:first + steps], r["truth"][i].tobytes() + grasps.tobytes())
        return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--steps", default="5,10,20", help="steps to compare (1-based, comma-separated)")
    ap.add_argument("--variant-a", help="variant label of A's runs (a store with a sweep)")
    ap.add_argument("--variant-b", help="variant label of B's runs (a store with a sweep)")
    ap.add_argument("--grasps-may-differ", action="store_true",
                    help="pair on the object pose and the first grasp only (active exploration)")
    ap.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples of the objects")
    ap.add_argument("--seed", type=int, default=1, help="seed of the bootstrap")
    ap.add_argument("--objects", help="only these explored objects (comma-separated names)")
    o = ap.parse_args()
    if o.resamples < 1:
        sys.exit("paired_runs: error: --resamples must be at least 1")
    A, B = load(o.a, o.variant_a, o.grasps_may_differ), load(o.b, o.variant_b, o.grasps_may_differ)
    keys = sorted(set(A) & set(B))
    if o.objects:
        wanted = [x for x in o.objects.split(",") if x]
        present = {k[0] for k in keys}
        missing = [x for x in wanted if x not in present]
        if missing:
            sys.exit(f"paired_runs: error: --objects: {', '.join(missing)} not explored in both stores")
        keys = [k for k in keys if k[0] in set(wanted)]
    if not keys:
        sys.exit("paired_runs: error: the stores share no (object, run)")
    for k in keys:
        if A[k][1] != B[k][1]:
            sys.exit(f"paired_runs: error: run {k[1]} of {k[0]} differs in object pose or grasps: not paired")
    steps = [int(x) for x in o.steps.split(",")]
    n_steps = min(len(A[keys[0]][0]), len(B[keys[0]][0]))
    objects = sorted({k[0] for k in keys})
    print(f"{len(keys)} paired runs of {len(objects)} objects; A = {o.a}, B = {o.b}")
    print("  step  A right  B right  both  A only  B only  McNemar p (runs indep.)  objects B better / worse"
          "  sign p (objects indep.)  B - A, points (95 % bootstrap over objects)")
    for st in steps:
        if not 1 <= st <= n_steps:
            sys.exit(f"paired_runs: error: --steps: step {st} outside 1..{n_steps}")
        a = np.array([A[k][0][st - 1] for k in keys])
        b = np.array([B[k][0][st - 1] for k in keys])
        both, a_only, b_only = int(np.sum(a & b)), int(np.sum(a & ~b)), int(np.sum(~a & b))
        better = worse = 0
        per_object, runs_of = [], []
        for obj in objects:
            d = sum(int(B[k][0][st - 1]) - int(A[k][0][st - 1]) for k in keys if k[0] == obj)
            per_object.append(d)
            runs_of.append(sum(1 for k in keys if k[0] == obj))
            better += d > 0
            worse += d < 0
        per_object, runs_of = np.array(per_object, dtype=float), np.array(runs_of, dtype=float)
        rng = np.random.default_rng([o.seed, st])   # a step's interval does not depend on the others asked
        boot = []
        for _ in range(o.resamples):
            pick = rng.integers(0, len(objects), len(objects))
            boot.append(per_object[pick].sum() / runs_of[pick].sum())
        lo, hi = np.percentile(boot, [2.5, 97.5])
        print(f"  {st:4d}  {100 * a.mean():6.1f}%  {100 * b.mean():6.1f}%  {both:4d}  {a_only:6d}  {b_only:6d}"
              f"  {two_sided_binomial(b_only, a_only + b_only):23.2g}"
              f"  {better:12d} / {worse:<5d}      {two_sided_binomial(better, better + worse):.2g}"
              f"                 {100 * (b.mean() - a.mean()):+.1f} ({100 * lo:+.1f} to {100 * hi:+.1f})")


if __name__ == "__main__":
    main()
