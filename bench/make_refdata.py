"""Regenerate the exact polyhedral geodesic references in ``tests/data/`` with pygeodesic (exact MMP,
a dev-only dependency: requirements-dev.txt).

    .venv/bin/python bench/make_refdata.py            # writes tests/data/geodesic_ref_*.npz
    .venv/bin/python bench/make_refdata.py --check    # only the flat-square sanity check
    .venv/bin/python bench/make_refdata.py --closed   # only the closed meshes' and suzanne's files
    .venv/bin/python bench/make_refdata.py --only ridge   # only one surface's file

Each file ``geodesic_ref_<surface>_<n>.npz`` holds ``sources`` (k,) int32 vertex indices and
``dist`` (k, n*n) float32 exact distances from each source to every vertex of
``core.surfaces.make_surface(surface, n)``. The generator first checks pygeodesic on a flat square,
where the exact answer is the Euclidean distance. ``geodesic_ref_<name>_closed.npz`` holds the same for
the closed meshes ``tests/data/sphere_<name>.npz`` (vertices as float64 of the stored float32), for
sphere mode's tests; ``geodesic_ref_suzanne_island.npz`` the largest island of tests/data/suzanne.obj
cut along its seams, with its ``V`` and ``F``; ``geodesic_ref_scan_patch.npz`` the scan-like disk
``tests/meshgen.scan_patch(1500, 3)``, and ``geodesic_ref_lifted_hemisphere.npz`` the lifted hemisphere
``tests/meshgen.steep_rim(2000, 1, 0.5, 1.0)``, ``geodesic_ref_bevel_box.npz`` the bevelled cube
``tests/meshgen.bevel_box(3, 0.2)``, and ``geodesic_ref_deepcap.npz`` the deep noisy cap
``core.surfaces.scan_like('deepcap')``, and ``geodesic_ref_finger.npz`` the narrow bump
``tests/meshgen.finger(65)``, each with its ``V`` and ``F`` (``--closed`` writes these too)."""
import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from core.surfaces import make_surface  # noqa: E402

DATA = os.path.join(ROOT, 'tests', 'data')

# (surface, n, sources): corner (-2,-2) is vertex 0, the centre is (n//2)*n + n//2, the midpoint
# of the edge y = -2 is n//2.
REFS = (
    ('bump', 129, (0, 8320, 64)),
    ('bump', 65, (0, 2112, 32)),
    ('edgebump', 65, (0, 2112, 32, 2138)),     # 2138: the peak, the vertex of largest angle defect
    ('bump3', 65, (2112,)),                    # the centre: the interior vertex of largest angle defect
)

# closed meshes (tests/data/sphere_<name>.npz) and sources: three vertices spread through the index order
CLOSED = (
    ('spot', (0, 976, 1953)),
    ('cheburashka', (0, 2223, 4446)),
)

# scan_patch(1500, 3): three vertices where the Steiner paths' extrapolation gains least (1.9-2.1x)
SCAN_SOURCES = (37, 1328, 1334)
# steep_rim(2000, 1, 0.5, 1.0), a lifted hemisphere: three vertices of its rim (the seed's needles)
HEMI_SOURCES = (90, 112, 149)
# bevel_box(3, 0.2), a coarse CAD-like part (flat faces of two triangles beside thin bevel strips):
# a corner, a bevel vertex and a face corner (the paths at k = 9 were 0.08-0.12 % off there)
BEVEL_SOURCES = (0, 100, 200)
# core.surfaces.scan_like('deepcap'), a deep noisy cap: the far source of bench/geodesic_real.py (a rim
# vertex; its re-marches' undershoot on given grids, docs/geodesic.md "Forty-first session")
DEEPCAP_SOURCES = (231,)
# tests/meshgen.finger(65), a square lifted into a narrow bump that its map shrinks 1000-fold: a vertex
# at (-0.9, 0), far from the finger, and the centre (0, 0), on its flank (docs/geodesic.md, "Forty-third
# session")
FINGER_SOURCES = (2083, 2112)


def suzanne_island():
    """(V (k,3), F (m,3)) of the largest island of tests/data/suzanne.obj cut along its OBJ seams (the
    UV islands of its ``vt`` indices), triangulated, with its own vertex numbering."""
    from core.atlas.islands import seams_from_corner_ids, unwrap
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    mesh = read_obj(os.path.join(DATA, 'suzanne.obj'))
    tc, _ = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
    F = mesh.corner_verts[tc]
    seams = seams_from_corner_ids(F, mesh.corner_uvs[tc], len(mesh.V))
    res = unwrap(mesh.V, F, seams=seams, boundary='area', pack=False, allow_loose=True)
    big = np.argmax(np.bincount(res.face_island))
    Fs = res.F[res.face_island == big]
    verts, Fl = np.unique(Fs, return_inverse=True)
    return mesh.V[res.vert_of[verts]].astype(np.float64), Fl.reshape(-1, 3).astype(np.int64)


def exact_distances(V, F, sources):
    """(k, n) float64 exact polyhedral geodesic distances from each vertex in ``sources``."""
    from pygeodesic import geodesic
    alg = geodesic.PyGeodesicAlgorithmExact(np.ascontiguousarray(V, np.float64),
                                            np.ascontiguousarray(F, np.int32))
    out = []
    for s in sources:
        d, _ = alg.geodesicDistances(np.array([s], np.int32), None)
        out.append(d)
    return np.array(out)


def check_flat():
    """pygeodesic on a flat square must give Euclidean distances."""
    V, F = make_surface('flat', 33)
    src = (0, 544, 16)
    D = exact_distances(V, F, src)
    E = np.linalg.norm(V[None, :, :] - V[list(src)][:, None, :], axis=2)
    err = np.abs(D - E).max()
    print(f"flat square 33x33: max |pygeodesic - Euclidean| = {err:.2e}")
    if err > 1e-9:
        raise SystemExit("pygeodesic does not reproduce Euclidean distances on a flat square")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--check', action='store_true', help='only run the flat-square check')
    ap.add_argument('--closed', action='store_true', help="only the closed meshes' and suzanne's files")
    ap.add_argument('--only', help='only this surface of REFS (e.g. ridge)')
    args = ap.parse_args(argv)
    check_flat()
    if args.check:
        return 0
    if args.only:
        return _surfaces([r for r in REFS if r[0] == args.only])
    for name, sources in CLOSED:
        d = np.load(os.path.join(DATA, f'sphere_{name}.npz'))
        V, F = d['V'].astype(np.float64), d['F'].astype(np.int64)
        D = exact_distances(V, F, sources)
        path = os.path.join(DATA, f'geodesic_ref_{name}_closed.npz')
        np.savez_compressed(path, sources=np.array(sources, np.int32), dist=D.astype(np.float32))
        print(f"{name} (closed) sources {sources}: max distance {D.max():.4f} -> "
              f"{os.path.relpath(path, ROOT)} ({os.path.getsize(path) // 1024} KB)")
    # the largest island of suzanne.obj cut along its OBJ seams, as a mesh of its own (a disk)
    Vi, Fi = suzanne_island()
    _mesh_ref('suzanne_island', "suzanne's largest island", Vi, Fi, (0, len(Vi) // 2, len(Vi) - 1))
    # a scan-like disk (random points, Delaunay-triangulated and lifted; tests/meshgen.py)
    sys.path.insert(0, os.path.join(ROOT, 'tests'))
    from meshgen import bevel_box, finger, scan_patch, steep_rim
    _mesh_ref('scan_patch', 'scan_patch(1500, 3)', *scan_patch(1500, 3), SCAN_SOURCES)
    # a lifted hemisphere (z = sqrt(1 - r^2) over random points: needles at its vertical rim)
    _mesh_ref('lifted_hemisphere', 'steep_rim(2000, 1, 0.5, 1.0)', *steep_rim(2000, 1, 0.5, 1.0),
              HEMI_SOURCES)
    # a bevelled cube (closed, coarse: few edges between any two points)
    _mesh_ref('bevel_box', 'bevel_box(3, 0.2)', *bevel_box(3, 0.2), BEVEL_SOURCES)
    # a deep noisy cap (scan-like: random points, Delaunay-triangulated, lifted with noise)
    from core.surfaces import scan_like
    _mesh_ref('deepcap', "scan_like('deepcap')", *scan_like('deepcap')[:2], DEEPCAP_SOURCES)
    # a narrow bump, a finger, that its conformal map shrinks 1000-fold (deep spots on a given grid)
    _mesh_ref('finger', 'finger(65)', *finger(65), FINGER_SOURCES)
    if args.closed:
        return 0
    return _surfaces(REFS)


def _mesh_ref(name, label, V, F, sources):
    """Write ``geodesic_ref_<name>.npz``: the mesh (``V`` float64 (k,3), ``F`` int32 (m,3)) with the
    exact distances from its vertices ``sources``; ``label`` names it in the printout."""
    D = exact_distances(V, F, sources)
    path = os.path.join(DATA, f'geodesic_ref_{name}.npz')
    np.savez_compressed(path, V=V.astype(np.float64), F=F.astype(np.int32),
                        sources=np.array(sources, np.int32), dist=D)
    print(f"{label} ({len(F)} triangles) sources {tuple(sources)} -> "
          f"{os.path.relpath(path, ROOT)} ({os.path.getsize(path) // 1024} KB)")


def _surfaces(refs):
    """Write ``geodesic_ref_<surface>_<n>.npz`` for each (surface, n, sources) of ``refs``."""
    for name, n, sources in refs:
        V, F = make_surface(name, n)
        t = time.perf_counter()
        D = exact_distances(V, F, sources)
        path = os.path.join(DATA, f'geodesic_ref_{name}_{n}.npz')
        np.savez_compressed(path, sources=np.array(sources, np.int32), dist=D.astype(np.float32))
        print(f"{name} n={n} sources {sources}: {time.perf_counter() - t:.1f} s, max distance "
              f"{D.max():.4f} -> {os.path.relpath(path, ROOT)} ({os.path.getsize(path) // 1024} KB)")
    return 0


if __name__ == '__main__':
    sys.exit(main())
