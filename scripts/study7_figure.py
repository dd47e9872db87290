#!/usr/bin/python3
"""Study 7's figures against database size: recognition at steps 5, 10, 20, 40 (Wilson 95 %
intervals, which assume independent runs) and the median time per step, from run stores of
`touchstone experiment`, on a log axis of database size.

    /usr/bin/python3 scripts/study7_figure.py STORE.h5 [STORE.h5 ...] --out FIG.png \
        [--label STORE.h5=catalogue ...] [--memory STORE.h5=1.6 ...] [--db-size STORE.h5=1.0 ...]
        [--build-time STORE.h5=5.6 ...] [--shared STORE.h5 ...]

A store's database size is its configuration's database_size, else the number of objects of
its database. Stores with the same label are joined by a line (default label: the store's
experiment name). --memory, --db-size and --build-time each add a panel: peak resident memory
of the experiment (GB), the database file (GB) and its build time (minutes), measured outside
(the stores do not hold them). --shared leaves a store out of the time panel: its steps were timed
on a machine shared with other jobs, so its times are not speed figures. Needs h5py and matplotlib (Debian's python3-h5py, python3-matplotlib).
"""
import argparse
import json
import math
import os
import sys

import h5py
import numpy as np


def text(x):
    return x.decode() if isinstance(x, bytes) else str(x)


def wilson(k, n, z=1.959964):
    if n == 0:
        return (0.0, 0.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def load(path):
    f = h5py.File(path, "r")
    raw = f["header/config"][()]
    if isinstance(raw, np.ndarray):
        raw = raw.reshape(-1)[0]
    config = json.loads(text(raw))
    size = config.get("database_size") or len(f["header/database_objects"])
    step = f["steps/step"][:]
    correct = f["steps/correct"][:].astype(bool)
    time_s = f["steps/time_s"][:]
    out = {"size": int(size), "name": config.get("name", os.path.basename(path)), "rate": {}, "time": {}}
    for s in sorted(set(step.tolist())):
        sel = step == s
        out["rate"][s] = (int(correct[sel].sum()), int(sel.sum()))
        out["time"][s] = float(np.median(time_s[sel]))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("stores", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--label", action="append", default=[], help="STORE=LABEL")
    ap.add_argument("--memory", action="append", default=[], help="STORE=GB")
    ap.add_argument("--db-size", action="append", default=[], help="STORE=GB")
    ap.add_argument("--build-time", action="append", default=[], help="STORE=minutes")
    ap.add_argument("--shared", action="append", default=[], help="STORE timed on a shared machine")
    ap.add_argument("--steps", default="5,10,20,40")
    a = ap.parse_args()
    os.environ.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = dict(x.split("=", 1) for x in a.label)
    extra = []   # (key, values per store, axis label) of the externally measured panels
    for key, values, ylabel in (("memory", a.memory, "peak resident memory (GB)"),
                                ("db_size", a.db_size, "database file (GB)"),
                                ("build_time", a.build_time, "database build (min)")):
        given = {k: float(v) for k, v in (x.split("=", 1) for x in values)}
        if given:
            extra.append((key, given, ylabel))
    steps = [int(s) for s in a.steps.split(",")]
    series = {}
    for path in a.stores:
        try:
            d = load(path)
        except (OSError, KeyError, ValueError) as e:
            sys.exit(f"study7_figure: error: cannot read {path}: {e}")
        for key, given, _ in extra:
            d[key] = given.get(path)
        d["shared"] = path in a.shared
        series.setdefault(labels.get(path, d["name"]), []).append(d)
    panels = 2 + len(extra)
    rows = 1 if panels <= 3 else 2
    cols = (panels + rows - 1) // rows
    fig, grid = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.2 * rows), squeeze=False)
    axes = list(grid.flat)
    for ax in axes[panels:]:
        ax.set_visible(False)
    axes = axes[:panels]
    markers = "osD^v"
    for li, (label, points) in enumerate(sorted(series.items())):
        points.sort(key=lambda d: d["size"])
        for si, s in enumerate(steps):
            have = [d for d in points if s in d["rate"]]
            if not have:
                continue
            xs = [d["size"] for d in have]
            k = [d["rate"][s] for d in have]
            y = [100.0 * c / n for c, n in k]
            ci = [wilson(c, n) for c, n in k]
            err = [[yy - 100 * lo for yy, (lo, hi) in zip(y, ci)], [100 * hi - yy for yy, (lo, hi) in zip(y, ci)]]
            axes[0].errorbar(xs, y, yerr=err, marker=markers[li % len(markers)], capsize=3,
                             color=f"C{si}", linestyle="-" if li == 0 else "--",
                             label=f"{label}, step {s}")
        timed = [d for d in points if not d["shared"]]
        t = [d["time"].get(20, d["time"][max(d["time"])]) for d in timed]
        axes[1].plot([d["size"] for d in timed], t, marker=markers[li % len(markers)], label=label)
        for pi, (key, _, _) in enumerate(extra):
            m = [(d["size"], d[key]) for d in points if d[key] is not None]
            if m:
                axes[2 + pi].plot([p[0] for p in m], [p[1] for p in m], marker=markers[li % len(markers)], label=label)
    axes[0].set_ylabel("recognized (%), Wilson 95 %")
    axes[0].set_ylim(0, 102)
    axes[1].set_ylabel("time per step at step 20, median (s)")
    for pi, (_, _, ylabel) in enumerate(extra):
        axes[2 + pi].set_ylabel(ylabel)
    sizes = [d["size"] for points in series.values() for d in points]
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlim(min(sizes) / 1.4, max(sizes) * 1.4)   # every panel on the same axis
        ax.set_ylim(bottom=0)
        ax.set_xlabel("objects in the database")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(a.out, dpi=110)
    print(f"study7_figure: {a.out}")


if __name__ == "__main__":
    main()
