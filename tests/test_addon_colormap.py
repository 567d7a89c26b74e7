"""The baking colour maps (addon/colormap.py, no bpy): perceptual lightness rises evenly, colours stay
in gamut, the fast table matches the exact OKLab path, and value normalisation behaves."""
import numpy as np
import pytest

from addon import colormap as cm

pytestmark = pytest.mark.bpy


def oklab_lightness(rgb_linear):
    """OKLab L of linear sRGB colours (k,3), computed independently of the module's inverse path."""
    M1 = np.array([[0.4122214708, 0.5363325363, 0.0514459929],
                   [0.2119034982, 0.6806995451, 0.1073969566],
                   [0.0883024619, 0.2817188376, 0.6299787005]])
    lms = np.cbrt(rgb_linear @ M1.T)
    return lms @ np.array([0.2104542553, 0.7936177850, -0.0040720468])


@pytest.mark.parametrize('name', ['PERCEPTUAL', 'HEAT', 'GRAY'])
def test_lightness_rises_evenly(name):
    t = np.linspace(0, 1, 201)
    c = cm.colormap_exact(t, name)
    L = oklab_lightness(c[:, :3].astype(float))
    steps = np.diff(L)
    assert (steps > 0).all()
    assert steps.max() < 2.0 * steps.mean()        # no flat or steep stretches
    assert L[-1] - L[0] > 0.6


def test_diverging_is_symmetric_in_lightness():
    t = np.linspace(0, 1, 101)
    L = oklab_lightness(cm.colormap_exact(t, 'DIVERGING')[:, :3].astype(float))
    assert np.argmax(L) == 50
    np.testing.assert_allclose(L[:50], L[::-1][:50], atol=0.02)


@pytest.mark.parametrize('name', list(cm.COLORMAPS))
def test_gamut_alpha_and_table(name):
    t = np.random.default_rng(0).random(5000)
    fast = cm.colormap(t, name)
    exact = cm.colormap_exact(t, name)
    assert fast.shape == (5000, 4) and fast.dtype == np.float32
    assert fast.min() >= 0 and fast.max() <= 1 and (fast[:, 3] == 1).all()
    np.testing.assert_allclose(fast, exact, atol=2e-3)


def test_perceptual_ends():
    srgb = cm.to_srgb8(cm.colormap([0.0, 1.0]))[:, :3].astype(int)
    dark, light = srgb
    assert dark[2] > dark[1] and dark.sum() < 250           # dark, bluish
    assert light[0] > 200 and light[1] > 200 and light[2] < 120   # yellow


def test_normalise():
    v = np.array([0.5, 1.0, 2.0])
    np.testing.assert_allclose(cm.normalise(v), [0, 0.5, 1])                 # log scale
    np.testing.assert_allclose(cm.normalise(v, log=False), [0, 1 / 3, 1])
    np.testing.assert_allclose(cm.normalise(np.array([1.0, 2.0]), centre=1.0), [0.5, 1.0])
    np.testing.assert_allclose(cm.normalise(np.full(4, 3.0)), 0.5)            # constant field
    with pytest.raises(ValueError):
        cm.colormap([0.5], 'NOPE')
