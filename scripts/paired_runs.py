#!/usr/bin/env python3
"""Paired comparison of two variants of run stores (touchstone experiment): per step, the share
recognized by each, the runs only one got right (a sign test on them), and a 95 % bootstrap of
the difference that resamples explored objects (the runs of one object share its pool and are
not independent).

  scripts/paired_runs.py A.h5 "LABEL_A" B.h5 "LABEL_B" [--steps 5 10 20] [--seed 1]

A label is a variant label as `touchstone report` prints it ("" for a store without a sweep).
Runs are paired by (object, run): both variants must come from the same seed and objects.
"""
import argparse
from math import comb

import h5py
import numpy as np


def load(path, label):
    with h5py.File(path, "r") as f:
        labels = [x.decode() if isinstance(x, bytes) else x for x in f["header/variant_labels"][:]]
        if label not in labels:
            raise SystemExit(f"{path}: no variant {label!r} (header/variant_labels: {labels})")
        v = labels.index(label)
        variant = f["runs/variant"][:]
        first = f["runs/first_step_row"][:]
        obj = f["runs/object"][:]
        run = f["runs/run"][:]
        step = f["steps/step"][:]
        correct = f["steps/correct"][:]
        out = {}
        for r in np.where(variant == v)[0]:
            rows = range(int(first[r]), len(step) if r + 1 >= len(first) else int(first[r + 1]))
            out[(int(obj[r]), int(run[r]))] = {int(step[i]): bool(correct[i]) for i in rows if i < len(step)}
        return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a")
    ap.add_argument("label_a")
    ap.add_argument("b")
    ap.add_argument("label_b")
    ap.add_argument("--steps", type=int, nargs="+", default=[5, 10, 20])
    ap.add_argument("--resamples", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    a, b = load(args.a, args.label_a), load(args.b, args.label_b)
    keys = sorted(set(a) & set(b))
    if not keys:
        raise SystemExit("no run is in both variants (same seed and objects?)")
    objects = sorted({k[0] for k in keys})
    rng = np.random.default_rng(args.seed)
    print(f"{len(keys)} paired runs of {len(objects)} objects")
    for s in args.steps:
        ka = np.array([a[k].get(s, False) for k in keys], float)
        kb = np.array([b[k].get(s, False) for k in keys], float)
        diff = np.array([sum(ka[i] - kb[i] for i, k in enumerate(keys) if k[0] == o) for o in objects])
        boots = [diff[rng.integers(0, len(objects), len(objects))].sum() / len(keys) for _ in range(args.resamples)]
        lo, hi = np.percentile(boots, [2.5, 97.5])
        up, down = int(((ka == 1) & (kb == 0)).sum()), int(((ka == 0) & (kb == 1)).sum())
        m = up + down
        p = min(1.0, 2 * sum(comb(m, i) for i in range(min(up, down) + 1)) / 2**m) if m else 1.0
        print(f"step {s}: A {100 * ka.mean():.1f} % B {100 * kb.mean():.1f} % difference "
              f"{100 * (ka.mean() - kb.mean()):+.1f} points (95 % bootstrap over objects {100 * lo:+.1f} to "
              f"{100 * hi:+.1f}); right in A only {up}, in B only {down} (sign test p = {p:.3f})")


if __name__ == "__main__":
    main()
