"""The test surfaces of DESIGN.md section 7: height fields z = f(x, y) on an n x n grid over [-2,2]^2."""
import numpy as np

from .errors import ConformalError

SURFACES = {
    'bump': lambda x, y: np.exp(-0.2 * x**2 - 0.5 * y**2),
    'bump3': lambda x, y: 3 * np.exp(-0.2 * x**2 - 0.5 * y**2),
    'edgebump': lambda x, y: 1.5 * np.exp(-((x - 1.6)**2 + y**2) / 0.3),
    'ridge': lambda x, y: np.exp(-4 * (x - 1.2)**2) + np.exp(-4 * (y + 1.2)**2),
    'saddle': lambda x, y: 0.4 * (x**2 - y**2),
    'flat': lambda x, y: 0.0 * x,
    # beyond DESIGN.md: checks of generality, on shapes the method was not tuned on
    'waves': lambda x, y: 0.3 * np.sin(2 * x) * np.cos(1.5 * y),
    'monkey': lambda x, y: 0.1 * (x**3 - 3 * x * y**2),
    'cliff': lambda x, y: 0.8 * np.tanh(3 * (x + y - 1.5)),
}


def grid_faces(n):
    """(2(n-1)^2, 3) int64 triangles of the n x n grid: quads split as (a,b,c), (a,c,d)."""
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing='ij')
    a = (i * n + j).ravel()
    b, c, d = a + 1, a + n + 1, a + n
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def make_surface(name, n):
    """Surface ``name`` on an n x n grid: ``V`` (n*n,3) float64, ``F`` (2(n-1)^2,3) int64. Vertex
    k = i*n + j sits at x = t[j], y = t[i], t = linspace(-2, 2, n)."""
    if name not in SURFACES:
        raise ConformalError(f"unknown surface {name!r}: choose one of {', '.join(SURFACES)}")
    if int(n) < 2:
        raise ConformalError(f"grid size must be at least 2, got {n}")
    n = int(n)
    t = np.linspace(-2, 2, n)
    X, Y = np.meshgrid(t, t)          # X[i,j] = t[j], Y[i,j] = t[i]
    Z = SURFACES[name](X, Y)
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1).astype(np.float64)
    return V, grid_faces(n)
