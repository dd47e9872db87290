#!/usr/bin/env python3
"""Recognize a tactile log against an object database, step by step, as `touchstone recognize
--log` does: the same settings, fusion and seed give the same answers.

    python3 recognize_log.py DATABASE.h5 LOG.h5 [SEED]

Needs the touchstone module on the path: PYTHONPATH=build/python from a build tree, or
PREFIX/lib/python3/dist-packages after `cmake --install`. Prints one line a step (the object,
its posterior, the pose's position) and, when the log carries its ground truth, the last step's
errors.
"""

import sys

import touchstone as ts


def main(argv):
    if len(argv) not in (3, 4):
        print("usage: recognize_log.py DATABASE.h5 LOG.h5 [SEED]", file=sys.stderr)
        return 2
    try:
        db = ts.Database(argv[1])
        log = ts.read_log(argv[2])
        # Touchstone's preset (the paper's method with its extensions), BRICPSF, one seed.
        recognizer = ts.Recognizer(db, preset="improved", method="bricpsf",
                                   seed=int(argv[3]) if len(argv) == 4 else 1)
        steps = recognizer.recognize_log(log)
    except ts.Error as e:  # bad input: the file and the field
        print(f"recognize_log.py: {e}", file=sys.stderr)
        return 1
    for r in steps:
        x, y, z = r.pose[:3, 3] if r.valid else (float("nan"),) * 3
        print(f"step {r.step:2d}  {r.object or '(none)':<24} posterior {r.posterior or 0.0:.3f}  "
              f"at ({x:+.4f}, {y:+.4f}, {z:+.4f}) m")
    last = steps[-1]
    if last.valid and last.position_error_m is not None:
        print(f"truth {log.object}: answer {'right' if last.correct else 'wrong'}, "
              f"position off by {1000 * last.position_error_m:.1f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
