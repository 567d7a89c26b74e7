"""Conformalized mean curvature flow (Kazhdan, Solomon and Ben-Chen 2012), the anchor for sphere mode,
and the angle error both are judged by.

cMCF: repeated backward-Euler steps ``(M + t L) V' = M V`` with the stiffness ``L`` (cotan Laplacian,
positive semidefinite) fixed from the original mesh and the lumped mass matrix ``M`` (a third of the
incident triangle areas per vertex) recomputed from the current positions each step. After each step
the surface is centred at its area centroid and rescaled to the area of the unit sphere (4 pi), so the
step ``t`` keeps its meaning. At the end every vertex is projected to the unit sphere. The flow
converges to a conformal map (up to a Moebius transformation, which the angle error does not see to
first order).

Angle error (the measure of issue #12): the mean over all corners of
``|angle of the flat triangle of the mapped vertices - angle of the mesh triangle|``, in degrees.

    .venv/bin/python bench/cmcf.py [--steps N] [--dt T] [--json OUT.json]

prints cMCF against ``core.sphere.map.sphere_map`` (``moebius='none'``) on spot and cheburashka
(tests/data) and on built meshes with thousands of negative cotan weights (``needle_blob``,
``jittered_blob``).
"""
import argparse
import json
import os
import sys
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from core.mesh.geometry import corner_angles, face_areas  # noqa: E402
from core.mesh.laplacian import cotan_laplacian  # noqa: E402


def angle_error(V: np.ndarray, F: np.ndarray, S: np.ndarray) -> float:
    """Mean over corners of |corner angle of the flat triangles of ``S`` (n,3) - corner angle of the
    mesh ``V`` (n,3), ``F`` (m,3)|, in degrees."""
    return float(np.degrees(np.abs(corner_angles(S, F) - corner_angles(V, F))).mean())


def sphere_flips(F: np.ndarray, S: np.ndarray) -> int:
    """Triangles whose flat image under ``S`` (n,3, on the unit sphere) faces the centre."""
    P = S[F]
    return int(((np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]) * P.mean(1)).sum(1) <= 0).sum())


def lumped_mass(V, F):
    """(n,) a third of the incident triangle areas per vertex."""
    return np.bincount(F.ravel(), np.repeat(face_areas(V, F) / 3.0, 3), minlength=len(V))


def _normalise(V, F):
    A = face_areas(V, F)
    c = (V[F].mean(1) * A[:, None]).sum(0) / A.sum()
    return (V - c) * np.sqrt(4.0 * np.pi / A.sum())


def cmcf(V: np.ndarray, F: np.ndarray, steps: int = 50, dt: float = 0.2, tol: float = 1e-7):
    """cMCF of the closed genus-0 mesh ``V`` (n,3), ``F`` (m,3): ``steps`` backward-Euler steps of
    size ``dt`` (on the surface rescaled to area 4 pi, so ``dt`` is in units of the squared unit-sphere
    radius), stopped early when the largest vertex move is below ``tol``. Returns (S (n,3) unit
    vectors, info dict with the steps taken)."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    X = _normalise(V, F)
    L = cotan_laplacian(X, F).tocsc()            # the stiffness: fixed, from the original (rescaled) mesh
    k = 0
    while k < steps:
        k += 1
        M = sp.diags(lumped_mass(X, F))
        Y = spla.splu((M + dt * L).tocsc()).solve(M @ X)
        Y = _normalise(Y, F)
        move = float(np.abs(Y - X).max())
        X = Y
        if move < tol:
            break
    S = X / np.linalg.norm(X, axis=1)[:, None]
    return S, {'steps': k, 'last_move': move}


def _read(path):
    from core.io.obj import read_obj
    m = read_obj(path)
    return m.V.astype(np.float64), m.triangles()[0].astype(np.int64)


def _npz(name):
    d = np.load(os.path.join(ROOT, 'tests', 'data', f'sphere_{name}.npz'))
    return d['V'].astype(np.float64), d['F'].astype(np.int64)


def needle_blob(k: int = 60, seed: int = 0, bumps=((0, 0, 1, 1.2), (1, 0, 0, 0.8), (0, -1, 0, 1.0)),
                width: float = 0.12):
    """A star-shaped blob (``core.surfaces.blob``'s radius function) triangulated with long thin
    triangles: a latitude-longitude grid of ``k`` rings and ``4k`` meridians whose quads are split along
    the diagonal that is *not* Delaunay, every other ring shifted by half a cell, vertices jittered
    along the rings. Thousands of negative cotan weights. Returns V (n,3), F (m,3) outward."""
    rng = np.random.default_rng(seed)
    nl = 4 * k
    th = np.pi * (np.arange(1, k) / k)
    ph = 2 * np.pi * (np.arange(nl)[None, :] + 0.5 * (np.arange(k - 1)[:, None] % 2)) / nl
    ph = ph + rng.uniform(-0.3, 0.3, ph.shape) * 2 * np.pi / nl
    V = np.stack([np.sin(th)[:, None] * np.cos(ph), np.sin(th)[:, None] * np.sin(ph),
                  np.cos(th)[:, None] * np.ones_like(ph)], -1).reshape(-1, 3)
    V = np.vstack([V, [[0, 0, 1]], [[0, 0, -1]]])
    r = np.ones(len(V))
    for dx, dy, dz, h in bumps:
        d = np.array([dx, dy, dz], float) / np.linalg.norm([dx, dy, dz])
        r += h * np.exp(-(1.0 - V @ d) / width)
    V = V * r[:, None]
    N, Sp = len(V) - 2, len(V) - 1
    idx = np.arange((k - 1) * nl).reshape(k - 1, nl)
    a, b = idx[:-1], np.roll(idx[:-1], -1, axis=1)
    c, d = np.roll(idx[1:], -1, axis=1), idx[1:]
    # long diagonal a-c or b-d, whichever is longer (non-Delaunay on purpose)
    lac = np.linalg.norm(V[a] - V[c], axis=-1)
    lbd = np.linalg.norm(V[b] - V[d], axis=-1)
    use_ac = lac >= lbd
    T1 = np.where(use_ac[..., None], np.stack([a, d, c], -1), np.stack([a, d, b], -1))
    T2 = np.where(use_ac[..., None], np.stack([a, c, b], -1), np.stack([b, d, c], -1))
    top = np.stack([np.full(nl, N), idx[0], np.roll(idx[0], -1)], -1)
    bot = np.stack([np.full(nl, Sp), np.roll(idx[-1], -1), idx[-1]], -1)
    F = np.vstack([top, T1.reshape(-1, 3), T2.reshape(-1, 3), bot])
    # outward orientation
    P = V[F] / r[F][..., None]
    out = (np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]) * P.mean(1)).sum(1) > 0
    F[~out] = F[~out][:, ::-1]
    return V, F


def jittered_blob(freq: int = 48, amount: float = 0.35, seed: int = 1):
    """``core.surfaces.blob`` with every vertex moved tangentially by up to ``amount`` of the local
    edge length (random; 0.35 keeps every triangle facing outwards, 0.45 would fold some in 3D): many
    obtuse triangles and negative cotan weights, the same surface shape."""
    from core.surfaces import blob
    V, F = blob(freq)
    rng = np.random.default_rng(seed)
    e = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    n = np.zeros_like(V)
    P = V[F]
    fn = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    for k in range(3):
        np.add.at(n, F[:, k], fn)
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = rng.normal(size=V.shape)
    d -= (d * n).sum(1)[:, None] * n
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    return V + amount * e * rng.uniform(0, 1, (len(V), 1)) * d, F


def negative_weights(V, F):
    L = sp.triu(cotan_laplacian(V, F), 1)
    return int((L.data > 1e-12).sum())            # off-diagonal -w_ij > 0: negative weight


def meshes():
    yield 'spot', _npz('spot')
    yield 'cheburashka', _npz('cheburashka')
    yield 'needle blob k=40', needle_blob(40)
    yield 'jittered blob', jittered_blob()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--steps', type=int, default=50)
    ap.add_argument('--dt', type=float, default=0.2)
    ap.add_argument('--json', help='write the rows as JSON')
    args = ap.parse_args(argv)
    from core.sphere.map import sphere_map
    rows = []
    print('| mesh | faces | negative cotan weights | cMCF angle err (deg) | cMCF folds | cMCF s '
          '| sphere_map angle err | folds | qc_mean | s |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for name, (V, F) in meshes():
        t = time.perf_counter()
        S, info = cmcf(V, F, steps=args.steps, dt=args.dt)
        tc = time.perf_counter() - t
        t = time.perf_counter()
        res = sphere_map(V, F, moebius='none')
        ts = time.perf_counter() - t
        r = dict(mesh=name, faces=len(F), negative=negative_weights(V, F),
                 cmcf_err=angle_error(V, F, S), cmcf_flips=sphere_flips(F, S), cmcf_s=tc,
                 cmcf_steps=info['steps'], err=angle_error(V, F, res.S), flips=res.report['flips'],
                 qc_mean=res.report['qc_mean'], s=ts)
        rows.append(r)
        print(f"| {name} | {r['faces']} | {r['negative']} | {r['cmcf_err']:.3f} | {r['cmcf_flips']} "
              f"| {tc:.1f} | {r['err']:.3f} | {r['flips']} | {r['qc_mean']:.4f} | {ts:.1f} |", flush=True)
    if args.json:
        with open(args.json, 'w') as fh:
            json.dump(rows, fh, indent=1)


if __name__ == '__main__':
    main()
