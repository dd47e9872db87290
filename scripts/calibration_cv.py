#!/usr/bin/python3
"""Which confidence model to fit: variants cross-validated over the explored objects.

    /usr/bin/python3 scripts/calibration_cv.py STORE.h5 [STORE.h5 ...] [--pose]

STORE.h5: run stores of known objects (the calibration runs; never the held-out ones). Approximately mirrors
`touchstone calibrate`'s object model (--pose: the pose model): per range of steps (1, 2, 3, 5,
7, 9, 12, 16), logistic regression on standardized terms, the L2 penalty from the same grid by
the least log loss in 5 folds by explored object, Newton's method. Each variant is scored out of
fold (5 folds by explored object, the model of each fold fitted on the others): expected
calibration error (10 bins) at steps 5, 10, 20 and over all steps, and the log loss (a proper
score: lower is better, and less noisy than the ECE). Variants: linear (the features), quadratic
(the features and their squares), and each with Platt scaling of its logit on out-of-fold logits.
Needs numpy and h5py.
"""
import argparse
import h5py
import numpy as np

FEATS = ["posterior_best", "posterior_margin", "log_residual", "agreement", "log_contacts", "log_step",
         "fit_rms_sigma", "fit_far_share", "fit_far10_share", "fit_offset_sigma", "free_conflict",
         "fit_worst_grasp_sigma", "fit_normal_rms_deg", "fit_normal_worst_deg", "posterior_entropy"]
RANGES = [1, 2, 3, 5, 7, 9, 12, 16]


def text(a):
    return [x.decode() if isinstance(x, bytes) else x for x in a[()]]


def load(path):
    with h5py.File(path, "r") as f:
        names = text(f["header/step_values"])
        objects = text(f["header/objects"])
        dbo = text(f["header/database_objects"]) if "header/database_objects" in f else objects
        obj, first = f["runs/object"][()], f["runs/first_step_row"][()]
        nsteps = [g.shape[0] for g in f["runs/grasps"][()]]
        values, correct = f["steps/values"][()], f["steps/correct"][()]
        poserr = f["steps/position_error_m"][()]
        variant = f["runs/variant"][()]
    if POSE:
        correct = correct.astype(bool) & (poserr < 0.01)
    cols = [names.index("feature." + n) for n in FEATS]
    X, y, step, grp = [], [], [], []
    for k, (o, r0) in enumerate(zip(obj, first)):
        if variant[k] < 0:   # padding of an interrupted append
            continue
        n = nsteps[k]
        for s in range(n):
            X.append(values[r0 + s, cols])
            y.append(bool(correct[r0 + s]))
            step.append(s + 1)
            grp.append(dbo.index(objects[o]))
    return np.array(X), np.array(y, float), np.array(step), np.array(grp)


def fit_logistic(X, y, l2):
    mean = X.mean(0)
    scale = np.maximum(X.std(0), 1e-9)
    Z = np.hstack([np.ones((len(X), 1)), np.clip((X - mean) / scale, -CLAMP, CLAMP)])
    w = np.zeros(Z.shape[1])
    P = np.eye(Z.shape[1]) * l2 * len(X)
    P[0, 0] = 1e-9
    for _ in range(100):
        z = Z @ w
        p = 1 / (1 + np.exp(-z))
        s = np.maximum(p * (1 - p), 1e-12)
        g = Z.T @ (y - p) - P @ w
        H = (Z * s[:, None]).T @ Z + P
        st = np.linalg.solve(H, g)
        w += st
        if np.abs(st).max() < 1e-10:
            break
    return mean, scale, w


def predict_logit(m, X):
    mean, scale, w = m
    return np.hstack([np.ones((len(X), 1)), np.clip((X - mean) / scale, -CLAMP, CLAMP)]) @ w


def logloss(p, y):
    p = np.clip(p, 1e-12, 1 - 1e-12)
    return -np.mean(y * np.log(p) + (1 - y) * np.log(1 - p))


CLAMP = 4.0   # standardized terms clamped, as touchstone calibrate does (kTermClamp)
GRID = [1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3]


def choose_l2(X, y, g, folds=5):
    best, bl = GRID[0], np.inf
    for l2 in GRID:
        ll = 0
        for f in range(folds):
            tr, te = g % folds != f, g % folds == f
            if te.sum() == 0 or tr.sum() == 0:
                continue
            m = fit_logistic(X[tr], y[tr], l2)
            ll += logloss(1 / (1 + np.exp(-predict_logit(m, X[te]))), y[te]) * te.sum()
        if ll < bl:
            best, bl = l2, ll
    return best


def range_of(step, ranges):
    k = 0
    while k + 1 < len(ranges) and ranges[k + 1] <= step:
        k += 1
    return k


def fit_model(X, y, step, g, ranges, transform, platt):
    Xt = transform(X)
    models = []
    for k, lo in enumerate(ranges):
        hi = ranges[k + 1] if k + 1 < len(ranges) else 10 ** 9
        sel = (step >= lo) & (step < hi)
        l2 = choose_l2(Xt[sel], y[sel], g[sel])
        m = fit_logistic(Xt[sel], y[sel], l2)
        ab = (1.0, 0.0)
        if platt:
            # out-of-fold logits within the range, then a 1-D logistic on them
            oof = np.zeros(sel.sum())
            Xs, ys, gs = Xt[sel], y[sel], g[sel]
            for f in range(5):
                tr, te = gs % 5 != f, gs % 5 == f
                oof[te] = predict_logit(fit_logistic(Xs[tr], ys[tr], l2), Xs[te])
            mm = fit_logistic(oof[:, None], ys, 1e-6)
            # logit' = w0 + w1 (oof - mean)/scale
            a = mm[2][1] / mm[1][0]
            b = mm[2][0] - a * mm[0][0]
            ab = (a, b)
        models.append((m, ab))
    return models


def predict(models, X, step, ranges, transform):
    Xt = transform(X)
    out = np.zeros(len(X))
    for i in range(len(X)):
        m, (a, b) = models[range_of(step[i], ranges)]
        out[i] = 1 / (1 + np.exp(-(a * predict_logit(m, Xt[i:i + 1])[0] + b)))
    return out


def ece(p, y, bins=10):
    b = np.minimum((p * bins).astype(int), bins - 1)
    e = 0
    for k in range(bins):
        s = b == k
        if s.sum():
            e += s.sum() / len(p) * abs(y[s].mean() - p[s].mean())
    return e


def ident(X):
    return X


def quadratic(X):
    return np.hstack([X, X ** 2])


VARIANTS = {
    "linear": (RANGES, ident, False),
    "linear + Platt": (RANGES, ident, True),
    "quadratic": (RANGES, quadratic, False),
    "quadratic + Platt": (RANGES, quadratic, True),
}
POSE = False


def main():
    global POSE
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("stores", nargs="+")
    p.add_argument("--pose", action="store_true", help="the pose model (right and within 1 cm)")
    a = p.parse_args()
    POSE = a.pose
    stores = a.stores
    parts = [load(p) for p in stores]
    X = np.vstack([p[0] for p in parts]); y = np.concatenate([p[1] for p in parts])
    step = np.concatenate([p[2] for p in parts]); g = np.concatenate([p[3] for p in parts])
    print("%s model, %d step answers (%d at step 20), out of fold over %d explored objects" % (
        "pose" if POSE else "object", len(y), (step == 20).sum(), len(set(g))))
    for name, (ranges, tr, platt) in VARIANTS.items():
        oof = np.zeros(len(y))
        for f in range(5):
            trn, te = g % 5 != f, g % 5 == f
            models = fit_model(X[trn], y[trn], step[trn], g[trn], ranges, tr, platt)
            oof[te] = predict(models, X[te], step[te], ranges, tr)
        row = []
        for s in (5, 10, 20):
            sel = step == s
            row.append("%d: %.3f" % (s, ece(oof[sel], y[sel])))
        print("%-18s ECE %s  all %.3f  logloss %.4f" % (name, "  ".join(row), ece(oof, y), logloss(oof, y)), flush=True)


if __name__ == "__main__":
    main()
