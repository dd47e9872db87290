#!/usr/bin/env python3
"""From Open3D to a recognition and back: Open3D meshes become a Touchstone database, an Open3D
point cloud of contacts is recognized, and the answer comes back as an Open3D mesh at its pose.

    python3 open3d_roundtrip.py OUT_DIR [OBJECT]

Needs Open3D (Debian: python3-open3d) and the touchstone module on the path (PYTHONPATH=
build/python from a build tree). Writes into OUT_DIR the database (db.h5), the contacts
(contacts.ply) and the answer's mesh placed where the recognizer found it (answer.ply).

1. Four Open3D primitives at their true size (metres) are the object database:
   ``ts.build_database`` takes each mesh's vertex and triangle arrays.
2. The contacts: here 12 simulated underwater grasps of OBJECT (default "cylinder"), turned into
   an ``open3d.geometry.PointCloud``, as contacts from a real hand would arrive.
3. ``Recognizer.step`` takes the cloud's points as an N x 3 array; the answer's mesh
   (``Database.mesh``) becomes an ``open3d.geometry.TriangleMesh`` moved by the answer's pose,
   and Open3D measures how far the contacts lie from it.
"""

import os
import sys

import numpy as np
import open3d as o3d

import touchstone as ts


def shapes():
    """Open3D primitives, metres: what a user's own meshes (o3d.io.read_triangle_mesh) would be."""
    box = o3d.geometry.TriangleMesh.create_box(0.12, 0.08, 0.05)
    cylinder = o3d.geometry.TriangleMesh.create_cylinder(radius=0.04, height=0.14, resolution=48)
    cone = o3d.geometry.TriangleMesh.create_cone(radius=0.05, height=0.11, resolution=48)
    torus = o3d.geometry.TriangleMesh.create_torus(torus_radius=0.05, tube_radius=0.018)
    return {"box": box, "cylinder": cylinder, "cone": cone, "torus": torus}


def main(argv):
    if len(argv) not in (2, 3):
        print("usage: open3d_roundtrip.py OUT_DIR [OBJECT]", file=sys.stderr)
        return 2
    out, touched = argv[1], argv[2] if len(argv) == 3 else "cylinder"
    os.makedirs(out, exist_ok=True)
    meshes = shapes()
    if touched not in meshes:
        print(f"open3d_roundtrip.py: OBJECT: one of {', '.join(meshes)}", file=sys.stderr)
        return 2
    try:
        # 1. Open3D meshes -> a database (each mesh's own size: scale="keep", in metres).
        db = ts.build_database(os.path.join(out, "db.h5"),
                               {name: (np.asarray(m.vertices), np.asarray(m.triangles))
                                for name, m in meshes.items()},
                               scale="keep", units="m")
        print(f"database: {', '.join(db.objects)}")

        # 2. Contacts as an Open3D point cloud (simulated here; a real hand's would be read with
        #    o3d.io.read_point_cloud).
        log = ts.simulate(db, touched, grasps=12, noise="underwater", seed=2)
        exploration = ts.Exploration(log, db)
        exploration.advance_to(len(log))
        contacts = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(exploration.contacts()))
        o3d.io.write_point_cloud(os.path.join(out, "contacts.ply"), contacts)

        # 3. The cloud -> a recognition.
        r = ts.Recognizer(db, seed=1).step(np.asarray(contacts.points))
    except ts.Error as e:
        print(f"open3d_roundtrip.py: {e}", file=sys.stderr)
        return 1
    if not r.valid:
        print(f"no answer from {len(contacts.points)} contacts")
        return 1

    # 4. The answer -> an Open3D mesh at its pose, and the contacts' distances to it.
    vertices, faces = db.mesh(r.object)
    answer = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(faces))
    answer.transform(r.pose)
    o3d.io.write_triangle_mesh(os.path.join(out, "answer.ply"), answer)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(answer))
    query = o3d.core.Tensor(np.asarray(contacts.points), dtype=o3d.core.Dtype.Float32)
    distance = scene.compute_distance(query).numpy()
    print(f"answer {r.object} (posterior {r.posterior:.3f}) from {len(contacts.points)} contacts; "
          f"touched {touched}: {'right' if r.object == touched else 'wrong'}")
    print(f"contacts to the answer's surface: median {1000 * np.median(distance):.2f} mm, "
          f"95th percentile {1000 * np.percentile(distance, 95):.2f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
