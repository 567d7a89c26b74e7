"""Colour maps for baking scalar fields into colour attributes. No bpy here, only numpy.

The maps are built in the OKLab colour space (perceptual lightness ``L``, chroma ``C``, hue ``h``):
lightness rises linearly along every map, so equal steps of the value look like equal steps of
brightness, and the colours stay readable in grey-scale prints. Out-of-gamut colours are pulled to the
sRGB gamut by lowering their chroma, never their lightness.

Colours come out as *linear* RGBA floats, the convention of Blender's FLOAT_COLOR attributes (scene
linear). ``linear_to_srgb`` converts them for an 8-bit PNG."""
import numpy as np

# name: (label, description)
COLORMAPS = {
    'PERCEPTUAL': ("Perceptual", "Dark blue through teal to yellow, lightness rising evenly (viridis-like)"),
    'HEAT': ("Heat", "Dark red through orange to pale yellow, lightness rising evenly"),
    'DIVERGING': ("Diverging", "Blue below the geometric mean, white at it, red above"),
    'GRAY': ("Gray", "Black to white"),
}

# Control points (t, L, C, hue in degrees) in OKLab LCh; linear interpolation in between.
_PATHS = {
    'PERCEPTUAL': [(0.0, 0.30, 0.11, 295.0), (0.35, 0.52, 0.10, 245.0), (0.65, 0.70, 0.13, 160.0),
                   (1.0, 0.93, 0.18, 105.0)],
    'HEAT': [(0.0, 0.25, 0.10, 20.0), (0.5, 0.62, 0.19, 45.0), (1.0, 0.96, 0.10, 100.0)],
    'DIVERGING': [(0.0, 0.45, 0.16, 260.0), (0.5, 0.97, 0.0, 260.0), (0.5, 0.97, 0.0, 30.0),
                  (1.0, 0.45, 0.17, 30.0)],
    'GRAY': [(0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.0)],
}

# OKLab -> LMS' (cube roots) and LMS -> linear sRGB matrices (Ottosson 2020).
_LAB_TO_LMS = np.array([[1.0, 0.3963377774, 0.2158037573],
                        [1.0, -0.1055613458, -0.0638541728],
                        [1.0, -0.0894841775, -1.2914855480]])
_LMS_TO_RGB = np.array([[4.0767416621, -3.3077115913, 0.2309699292],
                        [-1.2684380046, 2.6097574011, -0.3413193965],
                        [-0.0041960863, -0.7034186147, 1.7076147010]])


def oklch_to_linear(L, C, h_deg):
    """OKLab lightness/chroma/hue (each (k,)) to linear sRGB (k,3), not clipped."""
    h = np.radians(h_deg)
    lab = np.stack([L, C * np.cos(h), C * np.sin(h)], axis=1)
    lms = (lab @ _LAB_TO_LMS.T) ** 3
    return lms @ _LMS_TO_RGB.T


def _in_gamut(rgb, tol=1e-6):
    return ((rgb >= -tol) & (rgb <= 1 + tol)).all(axis=1)


def _path(name, t):
    pts = np.array(_PATHS[name], float)
    L = np.interp(t, pts[:, 0], pts[:, 1])
    C = np.interp(t, pts[:, 0], pts[:, 2])
    H = np.interp(t, pts[:, 0], pts[:, 3])
    if name == 'DIVERGING':          # two hue branches meeting at white
        H = np.where(t < 0.5, pts[0, 3], pts[-1, 3])
    return L, C, H


_LUT_SIZE = 4096
_luts = {}


def colormap(t, name='PERCEPTUAL'):
    """Map ``t`` (k,) in [0,1] (clipped; NaN -> 0) to linear RGBA (k,4) float32 with alpha 1.
    Looks up the nearest of 4096 entries of ``colormap_exact`` (within 2e-3 of it)."""
    if name not in _PATHS:
        raise ValueError(f"unknown colour map {name!r}: use one of {', '.join(_PATHS)}")
    lut = _luts.get(name)
    if lut is None:
        lut = _luts[name] = colormap_exact(np.linspace(0.0, 1.0, _LUT_SIZE), name)
    t = np.clip(np.nan_to_num(np.asarray(t, float).ravel(), nan=0.0), 0.0, 1.0)
    return lut[np.rint(t * (_LUT_SIZE - 1)).astype(np.intp)]


def colormap_exact(t, name='PERCEPTUAL'):
    """``colormap`` computed directly in OKLab, for every value (slower)."""
    t = np.clip(np.nan_to_num(np.asarray(t, float).ravel(), nan=0.0), 0.0, 1.0)
    L, C, H = _path(name, t)
    rgb = oklch_to_linear(L, C, H)
    bad = ~_in_gamut(rgb)
    if bad.any():                     # bisection on the chroma scale, per colour
        lo = np.zeros(bad.sum())
        hi = np.ones(bad.sum())
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            ok = _in_gamut(oklch_to_linear(L[bad], C[bad] * mid, H[bad]))
            lo = np.where(ok, mid, lo)
            hi = np.where(ok, hi, mid)
        rgb[bad] = oklch_to_linear(L[bad], C[bad] * lo, H[bad])
    out = np.ones((len(t), 4), np.float32)
    out[:, :3] = np.clip(rgb, 0.0, 1.0)
    return out


def normalise(values, lo=None, hi=None, log=True, centre=None):
    """Map ``values`` (k,) to [0,1] between ``lo`` and ``hi`` (defaults: their min and max), on a log
    scale if ``log``. With ``centre`` the range is made symmetric about it (for the diverging map).
    A constant field maps to 0.5."""
    v = np.asarray(values, float)
    lo = np.nanmin(v) if lo is None else lo
    hi = np.nanmax(v) if hi is None else hi
    f = np.log if log else (lambda x: np.asarray(x, float))
    with np.errstate(divide='ignore', invalid='ignore'):
        a, b, x = f(lo), f(hi), f(v)
        if centre is not None:
            c = f(centre)
            r = max(abs(a - c), abs(b - c))
            a, b = c - r, c + r
    if not np.isfinite(a) or not np.isfinite(b) or b - a <= 1e-12 * max(1.0, abs(a), abs(b)):
        return np.full(v.shape, 0.5)
    return np.clip((x - a) / (b - a), 0.0, 1.0)


def linear_to_srgb(rgb):
    """Linear [0,1] floats to sRGB-encoded [0,1] floats (same shape)."""
    rgb = np.clip(np.asarray(rgb, float), 0.0, 1.0)
    return np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * rgb ** (1 / 2.4) - 0.055)


def to_srgb8(rgba):
    """Linear RGBA (k,4) floats to sRGB RGBA (k,4) uint8."""
    out = np.empty(np.shape(rgba), np.uint8)
    out[..., :3] = np.round(linear_to_srgb(np.asarray(rgba)[..., :3]) * 255)
    out[..., 3] = np.round(np.clip(np.asarray(rgba)[..., 3], 0, 1) * 255)
    return out
