#!/usr/bin/python3
"""Contact sheet of a `touchstone catalogue` folder: a PNG grid of objects (one per family first).

usage: scripts/catalogue_sheet.py CATALOGUE_DIR OUT.png [--count 16] [--names a,b,...]
Needs numpy and matplotlib (/usr/bin/python3 on Debian: python3-matplotlib).
"""
import argparse
import os
import struct

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402


def read_ply(path):
    """Binary little-endian PLY as written by io/mesh_export.cpp (float xyz, uchar/int lists)."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    nv = nf = 0
    for line in data[:end].decode("ascii").splitlines():
        if line.startswith("element vertex"):
            nv = int(line.split()[2])
        elif line.startswith("element face"):
            nf = int(line.split()[2])
    v = np.frombuffer(data, dtype="<f4", count=3 * nv, offset=end).reshape(nv, 3)
    rec = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    f = np.frombuffer(data, dtype=rec, count=nf, offset=end + 12 * nv)["i"]
    return v.astype(float), f


def read_catalogue(folder):
    rows = []
    with open(os.path.join(folder, "catalogue.tsv")) as f:
        header = None
        for line in f:
            if line.startswith("#"):
                continue
            cols = line.rstrip("\n").split("\t")
            if header is None:
                header = cols
                continue
            rows.append(dict(zip(header, cols)))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("out")
    ap.add_argument("--count", type=int, default=16)
    ap.add_argument("--names", default="")
    a = ap.parse_args()
    rows = read_catalogue(a.folder)
    if a.names:
        wanted = a.names.split(",")
        pick = [r for r in rows if r["name"] in wanted]
    else:
        pick, seen = [], set()
        for r in rows:  # one per family, then the rest in order
            if r["family"] not in seen:
                seen.add(r["family"])
                pick.append(r)
        pick += [r for r in rows if r not in pick]
        pick = pick[: a.count]
    cols = int(np.ceil(np.sqrt(len(pick))))
    rows_n = int(np.ceil(len(pick) / cols))
    fig = plt.figure(figsize=(3.2 * cols, 3.4 * rows_n))
    light = np.array([0.4, -0.5, 0.8])
    light /= np.linalg.norm(light)
    for k, r in enumerate(pick):
        v, f = read_ply(os.path.join(a.folder, "meshes", r["name"] + ".ply"))
        tri = v[f]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-30
        shade = 0.25 + 0.75 * np.clip(n @ light, 0, 1)
        colors = np.c_[0.55 * shade, 0.65 * shade, 0.8 * shade, np.ones_like(shade)]
        ax = fig.add_subplot(rows_n, cols, k + 1, projection="3d")
        ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors="none"))
        lo, hi = v.min(0), v.max(0)
        c, h = (lo + hi) / 2, (hi - lo).max() / 2
        ax.set_xlim(c[0] - h, c[0] + h)
        ax.set_ylim(c[1] - h, c[1] + h)
        ax.set_zlim(c[2] - h, c[2] + h)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=25, azim=-60)
        ax.set_axis_off()
        ax.set_title(f"{r['name']}\n{float(r['extent_m']) * 1000:.0f} mm, {r['triangles']} tri", fontsize=8)
    fig.tight_layout()
    fig.savefig(a.out, dpi=90)


if __name__ == "__main__":
    main()
