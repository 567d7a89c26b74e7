"""Polthier's midedge conformal map and the paper's restricted boundary family (core.disk.midedge)."""
import numpy as np
import pytest

from core.errors import ConformalError
from core.mesh.laplacian import face_gradients, gradient
from core.mesh.measures import uv_measures
from core.disk.midedge import (RestrictedFamily, conjugate_midedge, cr_gradient, lp_restricted,
                          map_measures, midedge_edges, midedge_map, optimise_restricted,
                          restricted_map)
from core.surfaces import icosphere
from core.surfaces import make_surface


def cr_defect(V, F, mm):
    """Largest per-triangle |grad v - n x grad u| over the kept faces, relative to max |grad u|."""
    G, N, _ = face_gradients(V, F)
    gu = gradient(G, F, np.nan_to_num(mm.u))
    gv = cr_gradient(G, mm.FE, np.nan_to_num(mm.v))
    d = np.linalg.norm(gv - np.cross(N, gu), axis=1)[mm.keep]
    return d.max() / np.linalg.norm(gu[mm.keep], axis=1).max()


def test_edges_opposite_corners():
    V, F = make_surface('bump', 5)
    E, FE = midedge_edges(F)
    assert len(E) == 2 * 4 * 5 + 4 * 4          # grid edges plus one diagonal per quad
    for c in range(3):
        ends = np.sort(F[:, [(c + 1) % 3, (c + 2) % 3]], axis=1)
        assert (E[FE[:, c]] == ends).all()


@pytest.mark.parametrize('name,cut', [('bump', 0), ('bump', 100), ('saddle', 37)])
def test_uncontrolled_map_is_discrete_cauchy_riemann(name, cut):
    """Algorithm 1: in every kept triangle the Crouzeix-Raviart gradient of v is the 90-degree rotation
    of the gradient of u, to solver precision, and the map keeps orientation."""
    V, F = make_surface(name, 17)
    mm = midedge_map(V, F, cut_face=cut)
    assert cr_defect(V, F, mm) < 1e-10
    assert mm.report['cr_residual'] < 1e-10
    assert not mm.keep[cut] and mm.keep.sum() == len(F) - 1
    assert np.isnan(mm.mu[cut]) and (mm.mu[mm.keep] > 0).all()
    # pinned values and the natural (Neumann) condition everywhere else
    pins = F[cut, :2]
    assert mm.u[pins[0]] == -1.0 and mm.u[pins[1]] == 1.0
    m = map_measures(V, F, mm)
    assert m['flips'] == 0 and m['qc_max'] < 1 + 1e-8


def test_uncontrolled_map_on_closed_sphere():
    """The algorithm's original setting, a closed genus-0 mesh with one face cut out."""
    V, F = icosphere(4)
    mm = midedge_map(V, F, cut_face=7)
    assert cr_defect(V, F, mm) < 1e-10
    assert map_measures(V, F, mm)['flips'] == 0


def test_conjugate_needs_harmonic_u():
    """The Cauchy-Riemann system is inconsistent for a non-harmonic u: the residual is large. (So the
    small residual above is a real check.)"""
    V, F = make_surface('bump', 9)
    rng = np.random.default_rng(1)
    _, res = conjugate_midedge(V, F, rng.standard_normal(len(V)))
    assert res > 1e-2


def test_medial_triangles_carry_the_map_jacobian():
    """mu from the medial triangles' images equals |grad u| (the paper's per-triangle factor)."""
    V, F = make_surface('bump', 13)
    mm = midedge_map(V, F, cut_face=0)
    Vm, Fm, UVm = mm.midedge_mesh(V, F)
    Pm, W = Vm[Fm], UVm[Fm]
    a3 = 0.5 * np.linalg.norm(np.cross(Pm[:, 1] - Pm[:, 0], Pm[:, 2] - Pm[:, 0]), axis=1)
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    a2 = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    G, _, _ = face_gradients(V, F)
    g = np.linalg.norm(gradient(G, F, np.nan_to_num(mm.u)), axis=1)[mm.keep]
    assert np.allclose(np.sqrt(a2 / a3), g, rtol=1e-9)
    mu = mm.mu[mm.keep]
    assert np.allclose(mu / mu.max(), g / g.max(), rtol=1e-12)


def test_flat_square_linear_boundary_values_give_a_similarity():
    """On a flat square, u_B = (x + y + 4) / 8 is in the restricted family (0 at the corner (-2,-2),
    1 at the opposite corner, monotone on each half); u is then that linear function, v = (y - x)/8 +
    const, and the map is a similarity: mu constant, image congruent to the scaled, rotated square."""
    V, F = make_surface('flat', 9)
    fam = RestrictedFamily(V, F)
    assert np.allclose(V[fam.B[0], :2], [-2, -2]) and np.allclose(V[fam.B[fam.h], :2], [2, 2])
    uB = (V[fam.B, 0] + V[fam.B, 1] + 4) / 8
    assert np.allclose(fam.boundary_values(fam.weights_from_values(uB)), uB)
    mm = restricted_map(V, F, uB)
    assert np.allclose(mm.u, (V[:, 0] + V[:, 1] + 4) / 8, atol=1e-12)
    mid = 0.5 * (V[mm.E[:, 0]] + V[mm.E[:, 1]])
    vexp = (mid[:, 1] - mid[:, 0]) / 8
    assert np.allclose(mm.v - mm.v.mean(), vexp - vexp.mean(), atol=1e-12)
    assert np.ptp(mm.mu) < 1e-12
    # the conforming vertex version reproduces the linear map too
    uv = mm.vertex_uv(V, F)
    vv = (V[:, 1] - V[:, 0]) / 8
    assert np.allclose(uv[:, 1] - uv[:, 1].mean(), vv - vv.mean(), atol=1e-12)
    m = uv_measures(V, F, uv)
    assert m['mu_ratio'] > 1 - 1e-10 and m['qc_max'] < 1 + 1e-10


def test_uncontrolled_bump_crowds_at_three_corners():
    """The paper's Figures 1-2: with no boundary control the conformal factor collapses at the three
    corners away from the cut (here the cut face touches the corner (-2,-2))."""
    V, F = make_surface('bump', 33)
    mm = midedge_map(V, F, cut_face=0)
    m = map_measures(V, F, mm)
    assert m['mu_ratio'] < 1e-5 and m['area_ratio'] < 1e-10
    c = V[F].mean(axis=1)[:, :2]
    small = np.argsort(np.where(mm.keep, mm.mu, np.inf))[:12]
    corners = {tuple(np.sign(p).astype(int)) for p in c[small]}
    assert corners == {(1, 1), (1, -1), (-1, 1)}
    assert np.all(np.abs(c[small]) > 1.5)


def test_soft_objective_gradient_and_bound():
    V, F = make_surface('bump', 9)
    fam = RestrictedFamily(V, F)
    rng = np.random.default_rng(0)
    z = fam.ramp() * (0.5 + rng.random(fam.nb))
    for p in (4.0, 64.0):
        f, g = fam.soft_objective(z, p)
        dz = rng.standard_normal(fam.nb)
        eps = 1e-6
        fd = (fam.soft_objective(z + eps * dz, p)[0] - fam.soft_objective(z - eps * dz, p)[0]) / (2 * eps)
        assert abs(fd - g @ dz) < 1e-6 * max(1.0, abs(fd))
        # exp(-f) = 1 / (||mu||_p ||1/mu||_p) is an upper bound of min mu / max mu
        r = fam.ratio(fam.harmonic(fam.boundary_values(z)))
        assert r <= np.exp(-f) + 1e-12


def test_optimised_family_improves_and_respects_constraints():
    V, F = make_surface('bump', 17)
    fam = RestrictedFamily(V, F, start=8)          # the middle of the edge y = -2
    mm, rep = optimise_restricted(V, F, family=fam, p_schedule=(8, 64), maxiter=150)
    assert rep['ratio'] > rep['ratio_initial'] + 0.2
    uB = mm.u[fam.B]
    h = fam.h
    assert uB[0] == 0.0 and abs(uB[h] - 1.0) < 1e-12
    assert (uB >= -1e-12).all() and (uB <= 1 + 1e-12).all()
    assert (np.diff(uB[:h + 1]) >= -1e-12).all() and (np.diff(np.r_[uB[h:], 0.0]) <= 1e-12).all()
    assert cr_defect(V, F, mm) < 1e-9
    m = map_measures(V, F, mm)
    assert abs(m['mu_ratio'] - rep['ratio']) < 1e-9 and m['flips'] == 0
    # the conforming vertex version of the map is fold-free and close to conformal
    mv = uv_measures(V, F, mm.vertex_uv(V, F))
    assert mv['flips'] == 0 and mv['qc_mean'] < 1.05


def test_lp_relaxation_small():
    V, F = make_surface('bump', 9)
    mm, rep = lp_restricted(V, F, rounds=2)
    assert len(rep['rounds']) >= 1 and 'ratio' in rep['rounds'][0]
    assert 0 < rep['ratio'] <= 1
    uB = mm.u[RestrictedFamily(V, F).B]
    assert uB.min() > -1e-9 and uB.max() < 1 + 1e-9
    assert cr_defect(V, F, mm) < 1e-8


def test_bad_input():
    V, F = make_surface('bump', 5)
    with pytest.raises(ConformalError, match='out of range'):
        midedge_map(V, F, cut_face=len(F))
    with pytest.raises(ConformalError, match='pins'):
        midedge_map(V, F, pins=(1, 1))
    with pytest.raises(ConformalError, match='not on the boundary'):
        RestrictedFamily(V, F, start=12)
    with pytest.raises(ConformalError, match='one value per boundary vertex'):
        restricted_map(V, F, np.zeros(3))
