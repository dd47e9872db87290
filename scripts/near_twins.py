#!/usr/bin/python3
"""Near-twin share of the misses in a run store (touchstone experiment output).

    /usr/bin/python3 scripts/near_twins.py STORE.h5 [--steps 5,10,20,40] [--misses]

A miss names a wrong object; it is a near-twin miss when the named object belongs to the
explored object's family. A family is the name without a trailing variant suffix `_v<k>`
(scripts/make_variants.py), a `-<k>` suffix, or a `touchstone catalogue` object's `_<NNNN>` index
(its family: `flange_blind_0005` is a `flange_blind`). Prints, per step, the runs,
the misses and how many of them are near-twin misses. --misses lists each miss: its variant,
explored and named objects, the true class's log-weight gap to the answer (what set answers are
calibrated on; inf: no hypothesis of its class), the truth's rank in the posterior (0: absent) and,
in a store run with a calibration's answer sets, whether its set held the truth. Needs h5py
(Debian's python3-h5py).
"""
import argparse
import os
import re
import sys

import h5py
import numpy as np


def family(name):
    return re.sub(r"(_v\d+|-\d+|_\d{4,})$", "", name)


def text(x):
    return x.decode() if isinstance(x, bytes) else str(x)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("store")
    ap.add_argument("--steps", default="5,10,20,40")
    ap.add_argument("--misses", action="store_true", help="list each miss (gap to the answer, posterior rank, set)")
    a = ap.parse_args()
    os.environ.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
    try:
        f = h5py.File(a.store, "r")
        names = [text(x) for x in f["header/database_objects"][:]]
        explored = [text(x) for x in f["header/objects"][:]]
        obj = f["runs/object"][:]
        first = f["runs/first_step_row"][:]
        best = f["steps/best_object"][:]
        correct = f["steps/correct"][:]
        step = f["steps/step"][:]
        rank = f["steps/true_rank"][:]
        variant = f["runs/variant"][:]
        labels = [text(x) for x in f["header/variant_labels"][:]] if "variant_labels" in f["header"] else []
        columns = [text(x) for x in f["header/step_values"][:]] if "step_values" in f["header"] else []
        values = f["steps/values"] if columns else None
    except (OSError, KeyError) as e:
        sys.exit(f"near_twins: {a.store}: not a readable run store ({e})")
    def column(name):
        return columns.index(name) if name in columns else None

    # set.truth_score (set.truth_gap_to_answer before classes without hypotheses were ranked by
    # the shape prior): the log-weight gap, or 1e6 plus the prior's gap outside the state
    gap_col = column("set.truth_score")
    if gap_col is None:
        gap_col = column("set.truth_gap_to_answer")
    covers_col = column("answer_set.covers")
    listed = []
    print(f"{a.store}: {len(obj)} runs")
    print(f"{'step':>5} {'runs':>5} {'misses':>7} {'near-twin':>10} {'share':>7}")
    for s in [int(x) for x in a.steps.split(",")]:
        runs = misses = twins = 0
        for r in range(len(obj)):
            rows = np.nonzero(step[first[r]:first[r] + 1000] == s)[0]
            if len(rows) == 0:
                continue
            k = first[r] + rows[0]
            if step[k] != s:
                continue
            runs += 1
            if correct[k] == 1:
                continue
            misses += 1
            b = best[k]
            if b >= 0 and family(names[b]) == family(explored[obj[r]]) and names[b] != explored[obj[r]]:
                twins += 1
            if a.misses:
                gap = values[k, gap_col] if gap_col is not None else float("nan")
                covers = values[k, covers_col] if covers_col is not None else float("nan")
                listed.append((s, labels[variant[r]] if variant[r] < len(labels) else "", explored[obj[r]],
                               names[b] if b >= 0 else "-", gap, int(rank[k]),
                               "-" if np.isnan(covers) else ("yes" if covers == 1 else "no")))
        if runs:
            share = f"{100.0 * twins / misses:.0f} %" if misses else "-"
            print(f"{s:>5} {runs:>5} {misses:>7} {twins:>10} {share:>7}")
    if a.misses:
        print(f"\n{'step':>5}  {'variant':<24} {'explored':<24} {'named':<24} {'gap (nats)':>11} {'rank':>5} {'set':>4}")
        for s, v, e, n, gap, rk, cov in listed:
            shown = f"{gap:>11.2e}" if not gap >= 1e6 else ("no hyp." if gap == float("inf") else f"prior+{gap - 1e6:.2f}")
            print(f"{s:>5}  {v:<24} {e:<24} {n:<24} {shown:>11} {rk:>5} {cov:>4}")


if __name__ == "__main__":
    main()
