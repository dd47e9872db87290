#!/usr/bin/python3
"""Scaled and perturbed variants of a manifest's meshes, for database-scalability studies.

    /usr/bin/python3 scripts/make_variants.py datasets/dev45.tsv --per-object 10 --out build/db450

writes OUT/meshes/<name>_v<k>.off and OUT/manifest.tsv listing, for every object of the input
manifest, the original (k = 0, under its own name) and per_object - 1 variants. A variant is the
original mesh stretched along a random direction (factor e^N(0, 0.15)) and displaced by a smooth
random field (amplitude 1.5 % of the object's size, two sinusoidal modes): a similar but
distinguishable shape, a hard distractor for the original. `touchstone db build --manifest
OUT/manifest.tsv` then scales every mesh to the database's maximum extent (so uniform scaling
alone would not change a shape; the stretch does). Deterministic for a seed.

Reads meshes in OFF format, from plain files or from members of tar archives (`ARCHIVE:MEMBER`
paths, as manifests allow). Needs numpy (Debian's python3-numpy for /usr/bin/python3).
"""
import argparse
import io
import os
import sys
import tarfile

import numpy as np


def read_manifest(path):
    base = os.path.dirname(os.path.abspath(path))
    entries = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            line = line.rstrip("\n")
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            parts = line.split("\t")
            if len(parts) != 3:
                sys.exit(f"make_variants: {path}:{number}: expected source<TAB>path<TAB>name")
            source, mesh, name = parts
            entries.append((source, mesh, name, base))
    return entries


def open_mesh_bytes(mesh, base):
    archive, sep, member = mesh.partition(":")
    if sep and (archive.endswith(".tar") or archive.endswith(".tar.gz") or archive.endswith(".tgz")):
        archive_path = archive if os.path.isabs(archive) else os.path.join(base, archive)
        with tarfile.open(archive_path) as tar:
            return tar.extractfile(member).read()
    path = mesh if os.path.isabs(mesh) else os.path.join(base, mesh)
    with open(path, "rb") as f:
        return f.read()


def parse_off(data, label):
    lines = []
    for raw in io.StringIO(data.decode("utf-8", errors="replace")):
        line = raw.split("#", 1)[0].strip()
        if line:
            lines.append(line.split())
    if not lines or lines[0][0] not in ("OFF", "COFF", "NOFF", "CNOFF"):
        sys.exit(f"make_variants: {label}: not an OFF mesh")
    head = lines[0][1:]
    row = 1
    if len(head) < 2:  # counts on their own line
        head = lines[1]
        row = 2
    nv, nf = int(head[0]), int(head[1])
    # Only x y z are kept (COFF colours and NOFF normals are dropped).
    verts = np.array([[float(t) for t in lines[row + i][:3]] for i in range(nv)], dtype=float)
    row += nv
    faces = []
    for i in range(nf):
        toks = lines[row + i]
        k = int(toks[0])
        faces.append([int(t) for t in toks[1:1 + k]])  # optional colour values are dropped
    return verts, faces


def variant(verts, rng):
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    centre = 0.5 * (lo + hi)
    size = float(np.max(hi - lo))
    x = verts - centre
    # Stretch along a random direction.
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    factor = float(np.exp(rng.normal(0.0, 0.15)))
    x = x + (factor - 1.0) * np.outer(x @ u, u)
    # Smooth displacement: two sinusoidal modes with wavelengths of 0.5-1.5 object sizes.
    for _ in range(2):
        k = rng.normal(size=3)
        k *= 2.0 * np.pi / (size * rng.uniform(0.5, 1.5) * np.linalg.norm(k))
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        phase = rng.uniform(0, 2 * np.pi)
        x = x + 0.015 * size * np.outer(np.sin(x @ k + phase), d)
    return x + centre


def write_off(path, verts, faces):
    with open(path, "w") as f:
        f.write(f"OFF\n{len(verts)} {len(faces)} 0\n")
        for v in verts:
            f.write(f"{v[0]:.9g} {v[1]:.9g} {v[2]:.9g}\n")
        for face in faces:
            f.write(f"{len(face)} " + " ".join(str(i) for i in face) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("manifest")
    parser.add_argument("--per-object", type=int, default=10,
                        help="meshes per object, the original included (default 10)")
    parser.add_argument("--out", required=True, help="output folder (meshes/ and manifest.tsv)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    if args.per_object < 1:
        sys.exit("make_variants: --per-object must be at least 1")
    entries = read_manifest(args.manifest)
    meshes = os.path.join(args.out, "meshes")
    os.makedirs(meshes, exist_ok=True)
    lines = []
    for index, (source, mesh, name, base) in enumerate(entries):
        verts, faces = parse_off(open_mesh_bytes(mesh, base), f"{args.manifest}: {name}")
        for k in range(args.per_object):
            vname = name if k == 0 else f"{name}_v{k}"
            file = os.path.join(meshes, vname + ".off")
            if k == 0:
                out = verts
            else:
                rng = np.random.default_rng([args.seed, index, k])
                out = variant(verts, rng)
            write_off(file, out, faces)
            lines.append(f"{source}\tmeshes/{vname}.off\t{vname}")
    tmp = os.path.join(args.out, "manifest.tsv.tmp")
    with open(tmp, "w") as f:
        f.write("# generated by scripts/make_variants.py "
                f"{os.path.basename(args.manifest)} --per-object {args.per_object} --seed {args.seed}\n")
        f.write("\n".join(lines) + "\n")
    os.replace(tmp, os.path.join(args.out, "manifest.tsv"))
    print(f"make_variants: {len(lines)} meshes in {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
