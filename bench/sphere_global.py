"""Is the Moebius optimiser's ``uniform`` result the global optimum? A brute-force check.

For each closed mesh, ``min mu / max mu`` of the conformal sphere map composed with the hyperbolic
translation ``phi_c`` is evaluated at 3000 random points ``c`` of the ball (|c| < 0.95), then refined by
random local search around the best one. The optimiser's result is printed beside it, and beside the
better of the centring and mean-|log area| baselines. Where the brute-force value is no better than
the optimiser's, the gain over the baselines is what the shape allows, not a solver shortfall.

    .venv/bin/python bench/sphere_global.py
"""
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from core.mesh.geometry import face_areas          # noqa: E402
from core.sphere.moebius import exact_ratio          # noqa: E402
from core.surfaces import blob   # noqa: E402
from core.sphere.map import conformal_sphere, sphere_map   # noqa: E402
from sphere import SHAPES, _data              # noqa: E402


def brute_force(S, F, A, samples=3000, seed=0):
    rng = np.random.default_rng(seed)
    C = rng.normal(size=(samples, 3))
    C /= np.linalg.norm(C, axis=1)[:, None]
    C *= 0.95 * rng.uniform(0, 1, size=(samples, 1)) ** (1 / 3)
    best_v, best_c = exact_ratio(S, F, A), np.zeros(3)
    for c in C:
        v = exact_ratio(S, F, A, c)
        if v > best_v:
            best_v, best_c = v, c
    for scale in (0.05, 0.02, 0.005):
        for _ in range(300):
            c = best_c + scale * rng.normal(size=3)
            if np.linalg.norm(c) < 0.99:
                v = exact_ratio(S, F, A, c)
                if v > best_v:
                    best_v, best_c = v, c
    return best_v


def main():
    print(f"{'mesh':16} {'best baseline':>13} {'uniform':>9} {'brute force':>11} {'seconds':>8}")
    cases = [('spot', _data('spot'))] + [(k, blob(24, **kw)) for k, kw in SHAPES.items()]
    for name, (V, F) in cases:
        t = time.perf_counter()
        res = sphere_map(V, F, moebius='uniform')
        base = max(v for k, v in res.report['baselines'].items() if k in ('center', 'area'))
        S = conformal_sphere(V, F)
        S = S[0] if isinstance(S, tuple) else getattr(S, 'S', S)
        bf = brute_force(S, F, face_areas(V, F))
        print(f"{name:16} {base:13.4f} {res.report['mu_ratio']:9.4f} {bf:11.4f} "
              f"{time.perf_counter() - t:8.1f}")
        sys.stdout.flush()


if __name__ == '__main__':
    main()
