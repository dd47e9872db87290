#!/usr/bin/python3
"""Study 13's figure, the paper's Figure 9 redrawn: one heat map per descriptor (FPFH, PFH,
SHOT, Spin Images) of the normalized mean Euclidean distances between the 19 basic shapes, for
the simulated scanner's clouds (top row), the scanner's points with 1 mm noise (middle row) and
the exploration simulator's tactile contacts under underwater noise (bottom row), coloured
as the paper's from yellow (no difference) to red (large), each panel titled with its
separability (mean between-shape / mean within-shape distance) and 1-NN same-shape rate.

    build/bench/study13_descriptors --out study13
    /usr/bin/python3 scripts/study13_figure.py study13 --out study13/figure9.png

Needs matplotlib and numpy (Debian's python3-matplotlib).
"""
import argparse
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

DESCRIPTORS = [("fpfh", "FPFH (33)"), ("pfh", "PFH (125)"), ("shot", "SHOT (352)"), ("spin", "Spin Images (153)")]
CLOUDS = [("scanner", "laser scanner"), ("taxel", "scanner + 1 mm noise"), ("contacts", "simulated contacts")]


def read_matrix(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f, delimiter="\t"))
    names = rows[0][1:]
    m = np.array([[float(x) for x in r[1:]] for r in rows[1:]])
    return names, m


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder", help="output folder of study13_descriptors")
    ap.add_argument("--out", required=True, help="PNG to write")
    args = ap.parse_args()

    sep = {}
    with open(os.path.join(args.folder, "separability.tsv"), newline="") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            sep[(r["cloud"], r["descriptor"])] = (float(r["ratio"]), float(r["nn_same_shape"]))

    fig, axes = plt.subplots(len(CLOUDS), 4, figsize=(24, 5.5 * len(CLOUDS)))
    for row, (cloud, cloud_title) in enumerate(CLOUDS):
        for col, (desc, desc_title) in enumerate(DESCRIPTORS):
            names, m = read_matrix(os.path.join(args.folder, f"D_{cloud}_{desc}.tsv"))
            ax = axes[row][col]
            im = ax.imshow(m, cmap="YlOrRd", vmin=0.0, vmax=1.0)
            ratio, nn = sep[(cloud, desc)]
            ax.set_title(f"{desc_title}, {cloud_title}\nbetween/within {ratio:.2f}, 1-NN same shape {nn:.2f}", fontsize=10)
            ax.set_xticks(range(len(names)))
            ax.set_yticks(range(len(names)))
            ax.set_xticklabels(names, rotation=90, fontsize=6.5)
            ax.set_yticklabels(names if col == 0 else [""] * len(names), fontsize=6.5)
    fig.colorbar(im, ax=axes, shrink=0.6, label="mean Euclidean distance / largest entry")
    fig.suptitle("Study 13: distances between the descriptors of the 19 basic shapes (the paper's Figure 9); "
                 "feature radius 1.5 cm, normal radius 1 cm")
    fig.savefig(args.out, dpi=110, bbox_inches="tight")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
