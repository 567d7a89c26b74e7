"""`make demo`: the paper's bump surface flattened in Blender through the bpy module, headless.

    .venv/bin/python tools/demo.py --out out/demo [--n 65] [--docs docs/img]

Builds the ``bump`` surface as a Blender mesh, runs ``bpy.ops.uv.conformal_flatten(boundary='UNIFORM')``
(the same path as the scripts in docs/blender.md), saves ``demo.blend`` and ``bump_uv.obj`` (with UVs),
and renders with Workbench (software OpenGL is enough; Cycles on the CPU is the fallback):

- ``mu.png``: the mesh coloured by the baked conformal factor (colour attribute);
- ``checker.png``: a checker texture through the new UVs: conformal means the squares stay square;
- ``uv_layout.png``: the UV layout, triangles coloured by their realised mu, drawn with numpy.

With ``--docs DIR`` small copies go to DIR for the README (under 300 KB each)."""
import argparse
import json
import os
import shutil
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from tools.blender_user import private_user_resources  # noqa: E402

private_user_resources('cf-demo-user-')

import numpy as np  # noqa: E402


def log(msg):
    print(f"[demo] {msg}", flush=True)


# --- images without extra dependencies ------------------------------------------------------------
def save_png(path, rgb):
    """Save ``rgb`` (h,w,3) or (h,w,4) sRGB floats in [0,1] (row 0 at the top) as a PNG via bpy."""
    import bpy
    h, w = rgb.shape[:2]
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :rgb.shape[2]] = rgb
    img = bpy.data.images.new(os.path.basename(path), w, h, alpha=True)
    img.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())     # Blender: bottom row first
    img.filepath_raw = path
    img.file_format = 'PNG'
    img.save()
    bpy.data.images.remove(img)


def checker_pixels(size=1024, checks=16):
    """(size,size,3) sRGB floats: a two-tone checker with ``checks`` squares per side and a thin line
    every 4 squares, so both squareness and orientation can be read."""
    i = np.arange(size)
    cell = (i * checks) // size
    a = (cell[:, None] + cell[None, :]) % 2
    light, dark = np.array([0.93, 0.91, 0.85]), np.array([0.18, 0.32, 0.52])
    img = np.where(a[..., None] == 0, light, dark)
    major = (i % (size * 4 // checks)) < 3
    img[major, :] = [0.85, 0.35, 0.15]
    img[:, major] = [0.85, 0.35, 0.15]
    return img


def draw_uv_layout(loop_uv, corner_verts, sizes, tri_corners, tri_rgb, size=1024, margin=24):
    """Rasterise a UV layout: triangles filled with flat colours ``tri_rgb`` (m,3) sRGB, polygon edges
    darkened, the unit square outlined. ``loop_uv`` (c,2). Returns (H,W,3) sRGB floats."""
    full = size + 2 * margin
    img = np.ones((full, full, 3))
    P = np.empty_like(loop_uv)
    P[:, 0] = margin + loop_uv[:, 0] * size                 # x to the right
    P[:, 1] = margin + (1 - loop_uv[:, 1]) * size           # v up -> rows down
    for tri, rgb in zip(tri_corners, tri_rgb):
        A, B, C = P[tri]
        x0, y0 = np.floor(np.minimum(np.minimum(A, B), C)).astype(int)
        x1, y1 = np.ceil(np.maximum(np.maximum(A, B), C)).astype(int)
        xs, ys = np.meshgrid(np.arange(max(x0, 0), min(x1, full - 1) + 1) + 0.5,
                             np.arange(max(y0, 0), min(y1, full - 1) + 1) + 0.5)
        det = (B[0] - A[0]) * (C[1] - A[1]) - (B[1] - A[1]) * (C[0] - A[0])
        if det == 0 or xs.size == 0:
            continue
        l1 = ((xs - A[0]) * (C[1] - A[1]) - (ys - A[1]) * (C[0] - A[0])) / det
        l2 = ((B[0] - A[0]) * (ys - A[1]) - (B[1] - A[1]) * (xs - A[0])) / det
        inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9)
        img[ys[inside].astype(int), xs[inside].astype(int)] = rgb
    # polygon edges (not the triangulation's diagonals), sampled at half-pixel steps
    start = np.r_[0, np.cumsum(sizes)[:-1]]
    nxt = np.arange(len(loop_uv)) + 1
    last = start + sizes - 1
    nxt[last] = start
    a, b = P, P[nxt]
    steps = np.maximum(2, np.ceil(2 * np.linalg.norm(b - a, axis=1)).astype(int))
    seg = np.repeat(np.arange(len(a)), steps)
    t = (np.arange(len(seg)) - np.repeat(np.cumsum(steps) - steps, steps)) / np.repeat(steps - 1, steps)
    pts = a[seg] + t[:, None] * (b[seg] - a[seg])
    px = np.clip(pts.astype(int), 0, full - 1)
    img[px[:, 1], px[:, 0]] = 0.75 * img[px[:, 1], px[:, 0]]
    # unit square
    for k in (margin, margin + size):
        img[k, margin:margin + size + 1] = 0.3
        img[margin:margin + size + 1, k] = 0.3
    return img


# --- scene -----------------------------------------------------------------------------------------
def look_at(obj, target):
    from mathutils import Vector
    d = Vector(target) - obj.location
    obj.rotation_euler = d.to_track_quat('-Z', 'Y').to_euler()


def setup_scene(obj, res):
    import bpy
    sc = bpy.context.scene
    cam = bpy.data.objects.new('Camera', bpy.data.cameras.new('Camera'))
    sc.collection.objects.link(cam)
    cam.location = (5.2, -6.4, 5.0)
    look_at(cam, (0.0, 0.15, 0.2))
    cam.data.lens = 48
    sc.camera = cam
    world = bpy.data.worlds.new('World')
    world.color = (0.9, 0.9, 0.9)
    sc.world = world
    sc.render.resolution_x, sc.render.resolution_y = res
    sc.render.resolution_percentage = 100
    sc.render.image_settings.file_format = 'PNG'
    sc.render.image_settings.color_mode = 'RGB'
    sc.render.image_settings.compression = 100
    sc.display_settings.display_device = 'sRGB'
    sc.view_settings.view_transform = 'Standard'
    sc.render.engine = 'BLENDER_WORKBENCH'
    sh = sc.display.shading
    sh.light = 'STUDIO'
    sh.show_specular_highlight = False
    sc.display.render_aa = '8'
    obj.data.shade_smooth()
    return sc


def checker_material(obj, path):
    import bpy
    img = bpy.data.images.new('checker', 1024, 1024)
    rgba = np.ones((1024, 1024, 4), np.float32)
    rgba[..., :3] = checker_pixels()
    img.pixels.foreach_set(rgba[::-1].ravel())
    img.filepath_raw = path
    img.file_format = 'PNG'
    img.save()
    img.pack()
    mat = bpy.data.materials.new('Checker')
    if mat.node_tree is None:            # Blender < 5.0 creates materials without nodes
        mat.use_nodes = True
    nt = mat.node_tree
    tex = nt.nodes.new('ShaderNodeTexImage')
    tex.image = img
    tex.interpolation = 'Cubic'
    bsdf = next(n for n in nt.nodes if n.type == 'BSDF_PRINCIPLED')
    nt.links.new(tex.outputs['Color'], bsdf.inputs['Base Color'])
    nt.nodes.active = tex
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    return mat


def render(sc, path, color_type):
    import bpy
    sc.display.shading.color_type = color_type
    sc.render.filepath = path
    try:
        bpy.ops.render.render(write_still=True)
        if os.path.exists(path):
            return 'Workbench'
    except RuntimeError as exc:
        log(f"Workbench failed ({exc}); trying Cycles on the CPU")
    sc.render.engine = 'CYCLES'
    sc.cycles.device = 'CPU'
    sc.cycles.samples = 16
    bpy.ops.render.render(write_still=True)
    sc.render.engine = 'BLENDER_WORKBENCH'
    return 'Cycles'


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', default=os.path.join(ROOT, 'out', 'demo'))
    ap.add_argument('--n', type=int, default=65, help="grid size of the bump surface")
    ap.add_argument('--boundary', default='UNIFORM', choices=['UNIFORM', 'AREA', 'FREE'])
    ap.add_argument('--res', type=int, nargs=2, default=(800, 600), help="render size")
    ap.add_argument('--uv-size', type=int, default=720, help="UV layout image size in pixels")
    ap.add_argument('--docs', default=None, help="also copy the PNGs here (small copies for the README)")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)

    import bpy
    from tools import devpkg
    pkg = devpkg.load()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    pkg.register()
    from conformal_flatten.core.io.obj import write_obj
    from conformal_flatten.core.surfaces import make_surface
    from conformal_flatten.addon import meshio
    from conformal_flatten.addon.colormap import colormap, linear_to_srgb, normalise

    # 1. the mesh, as a user would have it
    V, F = make_surface('bump', args.n)
    me = bpy.data.meshes.new('bump')
    me.from_pydata(V.tolist(), [], F.tolist())
    me.update()
    obj = bpy.data.objects.new('bump', me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)

    # 2. the operator, exactly as a script would call it
    t = time.perf_counter()
    bpy.ops.uv.conformal_flatten(boundary=args.boundary, fit='UNIT_SQUARE', bake=True)
    log(f"conformal_flatten: {time.perf_counter() - t:.2f} s")
    report = meshio.load_report(me, 'conformal_flatten_report')

    # 3. files: .blend and OBJ with UVs
    md = meshio.read_mesh(obj)
    uv_loop = meshio.read_uv(me)
    uv_vert = np.zeros((len(md.V), 2))
    uv_vert[md.corner_verts] = uv_loop
    polys = np.split(md.corner_verts, np.cumsum(md.sizes)[:-1])
    write_obj(os.path.join(out, 'bump_uv.obj'), md.V, polys, uv_vert)

    # 4. renders
    sc = setup_scene(obj, tuple(args.res))
    engines = {}
    engines['mu.png'] = render(sc, os.path.join(out, 'mu.png'), 'VERTEX')
    checker_material(obj, os.path.join(out, 'checker_texture.png'))
    engines['checker.png'] = render(sc, os.path.join(out, 'checker.png'), 'TEXTURE')
    from conformal_flatten.core.mesh.measures import conformal_factor
    mu_t = conformal_factor(md.V, md.F, uv_vert)              # realised per-triangle mu
    lo, hi = me['conformal_factor_range']
    rgb = linear_to_srgb(colormap(normalise(mu_t, mu_t.min(), mu_t.max(), log=True))[:, :3])
    layout = draw_uv_layout(uv_loop, md.corner_verts, md.sizes, md.tri_corners, rgb,
                            size=args.uv_size)
    save_png(os.path.join(out, 'uv_layout.png'), layout)
    engines['uv_layout.png'] = 'numpy'
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(out, 'demo.blend'), compress=True)

    summary = {'report': report, 'renders': engines, 'seconds': round(time.perf_counter() - t_start, 2)}
    with open(os.path.join(out, 'summary.json'), 'w') as fh:
        json.dump(summary, fh, indent=1)
    if args.docs:
        os.makedirs(args.docs, exist_ok=True)
        for name in ('mu.png', 'checker.png', 'uv_layout.png'):
            dst = os.path.join(args.docs, 'demo_' + name)
            shutil.copy(os.path.join(out, name), dst)
            log(f"{dst}: {os.path.getsize(dst) / 1e3:.0f} KB")
    log(f"mu ratio {report['mu_ratio']:.4f} (bound {report.get('bound_vertex') or float('nan'):.4f}), "
        f"{report['flips']} flips, qc mean {report['qc_mean']:.4f}, mu in [{lo:.4f}, {hi:.4f}]")
    log(f"wrote {out}/demo.blend, bump_uv.obj, mu.png, checker.png, uv_layout.png "
        f"in {summary['seconds']:.1f} s")
    pkg.unregister()
    return 0


if __name__ == '__main__':
    sys.exit(main())
