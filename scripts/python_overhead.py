#!/usr/bin/env python3
"""The Python module's overhead per recognition step over the C++ call it wraps.

For simulated logs of a database's objects, each step is run through Recognizer.step with the
fused clouds as NumPy arrays (the way a notebook steps its own data); the wall time of the
Python call is compared with the step's own time measured inside the C++ recognizer (times_s
"total"): the difference is what the binding adds (array conversion in, the result's dict, 4 x 4
arrays and hypotheses out). Prints the median per step and the overhead as a share.

    PYTHONPATH=build/python /usr/bin/python3 scripts/python_overhead.py --db build/dev45.h5 \\
        [--objects bunny,cow,pipe] [--grasps 20] [--threads 2]
"""

import argparse
import os
import platform
import statistics
import time

import touchstone as ts


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--db", required=True)
    ap.add_argument("--objects", default="bunny,cow,pipe", help="comma-separated database objects")
    ap.add_argument("--grasps", type=int, default=20)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()

    ts.set_threads(a.threads)
    db = ts.Database(a.db)
    wall, inner = [], []
    for name in a.objects.split(","):
        log = ts.simulate(db, name, grasps=a.grasps, noise="underwater", seed=a.seed)
        rec = ts.Recognizer(db, seed=1)
        ex = ts.Exploration(log, db)
        for k in range(1, a.grasps + 1):
            ex.advance_to(k)
            contacts, free, grasps = ex.contacts(), ex.free(), ex.grasps()
            hand_free, pivots = ex.hand_free(), ex.pivots()
            t0 = time.perf_counter()
            r = rec.step(contacts, free, grasps, hand_free, pivots)
            wall.append(time.perf_counter() - t0)
            inner.append(r.times_s["total"])
    over = [w - i for w, i in zip(wall, inner)]
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores, {a.threads} threads, Python {platform.python_version()}, "
          f"touchstone {ts.__version__}")
    print(f"steps: {len(wall)} ({a.objects}, {a.grasps} grasps each, underwater, one pad)")
    print(f"median step: Python call {1e3 * statistics.median(wall):.2f} ms, C++ step {1e3 * statistics.median(inner):.2f} ms")
    print(f"binding overhead per step: median {1e3 * statistics.median(over):.3f} ms, "
          f"max {1e3 * max(over):.3f} ms; total {100 * sum(over) / sum(inner):.2f} % of the C++ time")


if __name__ == "__main__":
    main()
