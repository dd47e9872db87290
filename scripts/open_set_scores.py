#!/usr/bin/python3
"""How a calibration's in-database score separates known from hidden objects at one step.

    /usr/bin/python3 scripts/open_set_scores.py --calibration CAL.json --known K.h5 --hidden H.h5 [--step 20]

K.h5: a run store of known objects; H.h5: one whose explored objects were hidden from the
recognizer (`--set hidden=each`), both recorded with the features CAL.json was fitted on. Prints,
at the step: how many right answers of K.h5 score below the file's open-set threshold, and of
which objects; the points of K.h5's recognition the threshold costs, with a 95 % interval from
resampling the explored objects (2 000 resamples, seed 1: the runs of one object are not
independent); the area under the ROC curve of the score between K.h5's right answers and H.h5's
answers; and each feature's own area (lower values for right answers). Needs numpy and h5py.
"""
import argparse
import json
from collections import Counter

import h5py
import numpy as np


def text(a):
    return [x.decode() if isinstance(x, bytes) else x for x in a[()]]


def rows(path, step):
    """(explored object, right, feature values by name) of every run at `step`."""
    with h5py.File(path, "r") as f:
        names = text(f["header/step_values"])
        objects = text(f["header/objects"])
        obj, first = f["runs/object"][()], f["runs/first_step_row"][()]
        values, correct = f["steps/values"][()], f["steps/correct"][()]
    out = []
    for o, row0 in zip(obj, first):
        r = row0 + step - 1
        out.append((objects[o], bool(correct[r]), dict(zip(names, values[r]))))
    return out


def area(higher, lower):
    """P(a value of `higher` exceeds one of `lower`), ties counted half."""
    higher, lower = np.asarray(higher), np.asarray(lower)
    return float(np.mean([(x > lower).mean() + 0.5 * (x == lower).mean() for x in higher]))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calibration", required=True)
    p.add_argument("--known", required=True)
    p.add_argument("--hidden", required=True)
    p.add_argument("--step", type=int, default=20)
    a = p.parse_args()
    cal = json.load(open(a.calibration))
    model = [s for s in cal["steps"] if s["first_step"] <= a.step][-1]["in_database"]
    t = cal["open_set_threshold"]

    def score(features):
        x = np.array([features["feature." + f] for f in cal["features"]])
        if model.get("terms") == "quadratic":   # version 3: the features, then their squares
            x = np.concatenate([x, x * x])
        t = (x - np.array(model["mean"])) / np.array(model["scale"])
        if model.get("clamp", 0) > 0:   # version 3: standardized terms clamped
            t = np.clip(t, -model["clamp"], model["clamp"])
        z = model["coef"][0] + np.dot(model["coef"][1:], t)
        return 1.0 / (1.0 + np.exp(-z))

    known, hidden = rows(a.known, a.step), rows(a.hidden, a.step)
    right = [(o, score(f)) for o, ok, f in known if ok]
    below = Counter(o for o, s in right if s < t)
    print("step %d, threshold %.3f: %d of %d right answers below it (%s)" % (
        a.step, t, sum(below.values()), len(right), ", ".join("%s %d" % kv for kv in below.most_common())))
    objects = sorted({o for o, _, _ in known})
    lost = np.array([below.get(o, 0) for o in objects])
    runs = np.array([sum(1 for k, _, _ in known if k == o) for o in objects])
    rng = np.random.RandomState(1)
    boot = []
    for _ in range(2000):
        i = rng.randint(0, len(objects), len(objects))
        boot.append(100.0 * lost[i].sum() / runs[i].sum())
    print("recognition lost: %.1f points (resampling the %d objects, 95 %%: %.1f-%.1f)" % (
        100.0 * lost.sum() / runs.sum(), len(objects), np.percentile(boot, 2.5), np.percentile(boot, 97.5)))
    print("area under the ROC curve, score, right known against hidden: %.3f" % area(
        [s for _, s in right], [score(f) for _, _, f in hidden]))
    for name in cal["features"]:
        k = [f["feature." + name] for _, ok, f in known if ok]
        h = [f["feature." + name] for _, _, f in hidden]
        print("  %-24s %.3f  (medians %.3g right known, %.3g hidden)" % (name, area(h, k), np.median(k), np.median(h)))


if __name__ == "__main__":
    main()
