"""Meshes made the way Blender users make them, built with bpy (the ``bpy`` wheel of the project's
venv) for the benchmarks' generalisation runs: voxel-remeshed shapes and decimated ones.

- ``figure``: a body, a head, two arms and two legs (UV spheres and cylinders) joined and
  voxel-remeshed (Remesh modifier, voxel size 0.05): closed, genus 0, 22k triangles, long limbs, a
  few slivers and near-coincident vertices the remesher leaves.
- ``hand``: a palm, four fingers and a thumb (a scaled UV sphere and cylinders) and a forearm, joined
  and voxel-remeshed at 0.04; cut at the wrist (``hand-wrist``) it is a disk whose fingers the
  conformal map shrinks 10^4-fold.
- ``part``: a bevelled slab with a cylindrical boss (Boolean union), voxel-remeshed at 0.04: a
  CAD-like closed part, 29k triangles.
- ``suzvox``: Suzanne voxel-remeshed at 0.05 (closed, genus 0, 13k triangles).
- ``figure-dec``, ``suzvox-dec``: the figure decimated to 10 % and Suzanne remeshed at 0.02 then
  decimated to 5 % (Decimate modifier, collapse): needles and slivers.
- ``cow-dec``, ``bunny-dec``: corpus meshes decimated to 20 % and 5 % (need ``corpus_dir()``).

``load(name)`` returns (V (n,3) float64, F (m,3) int64), triangulated as Blender does, with the
coordinates Blender stores (float32); None when a corpus mesh it needs is missing. ``CUTS`` are plane
cuts of them (``meshes.cut_disk``): disks for the planar geodesic solver."""
import os

import numpy as np

from meshes import corpus_dir

NAMES = ('figure', 'hand', 'part', 'suzvox', 'figure-dec', 'suzvox-dec', 'cow-dec', 'bunny-dec')
# name -> (mesh, direction, height): the figure above its waist (arms and head: long limbs), the
# part's top, Suzanne's face, the decimated figure's and Suzanne's, the decimated cow's rear, the hand
# above its wrist
CUTS = {'figure-upper': ('figure', (0, 0, 1), -0.6), 'part-top': ('part', (0, 0, 1), 0.1),
        'suzvox-front': ('suzvox', (0, -1, 0), 0.0), 'figure-dec-upper': ('figure-dec', (0, 0, 1), -0.6),
        'suzvox-dec-front': ('suzvox-dec', (0, -1, 0), 0.0), 'cow-dec-rear': ('cow-dec', (-1, 0, 0), 0.5),
        'hand-wrist': ('hand', (0, 0, 1), -1.4)}


def _arrays(ob):
    """(V, F) of the evaluated object ``ob`` (modifiers applied), triangulated by bmesh, as Blender's
    Triangulate and OBJ export give it. (The add-on's ``meshio.read_mesh`` reads the base mesh and
    ignores modifiers by design; these meshes are the modifiers' output.)"""
    import bmesh
    import bpy
    me = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    bm = bmesh.new()
    bm.from_mesh(me)
    bmesh.ops.triangulate(bm, faces=bm.faces[:])
    bm.to_mesh(me)
    bm.free()
    V = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get('co', V)
    F = np.empty(len(me.polygons) * 3, np.int32)
    me.polygons.foreach_get('vertices', F)
    return V.reshape(-1, 3).astype(np.float64), F.reshape(-1, 3).astype(np.int64)


def _modifier(ob, kind, **settings):
    m = ob.modifiers.new(kind.lower(), kind)
    for k, v in settings.items():
        setattr(m, k, v)
    return m


def _empty_scene():
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)


def _joined(parts, voxel):
    """The objects ``parts`` joined into the first, their transforms applied, with a voxel Remesh
    modifier of ``voxel`` size."""
    import bpy
    bpy.ops.object.select_all(action='DESELECT')
    for p in parts:
        p.select_set(True)
    bpy.context.view_layer.objects.active = parts[0]
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)
    bpy.ops.object.join()
    _modifier(parts[0], 'REMESH', mode='VOXEL', voxel_size=voxel)
    return parts[0]


def _ellipsoid(scale):
    """A fresh scene holding a unit UV sphere scaled by ``scale`` (3,): the list of its one object."""
    import bpy
    _empty_scene()
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0, 0, 0))
    bpy.context.active_object.scale = scale
    return [bpy.context.active_object]


def _figure():
    import bpy
    add = bpy.ops.mesh
    parts = _ellipsoid((0.8, 0.6, 1.2))
    add.primitive_uv_sphere_add(radius=0.55, location=(0, 0, 1.7))
    parts.append(bpy.context.active_object)
    for x, rot in ((0.9, 0.9), (-0.9, -0.9)):
        add.primitive_cylinder_add(radius=0.14, depth=2.0, location=(1.3 * x, 0, 0.3), rotation=(0, rot, 0))
        parts.append(bpy.context.active_object)
    for x in (0.35, -0.35):
        add.primitive_cylinder_add(radius=0.18, depth=2.2, location=(x, 0, -1.9))
        parts.append(bpy.context.active_object)
    return _joined(parts, 0.05)


def _hand():
    import bpy
    add = bpy.ops.mesh
    parts = _ellipsoid((0.9, 0.35, 1.0))
    for x, length in ((-0.5, 1.1), (-0.17, 1.35), (0.17, 1.3), (0.5, 1.0)):
        add.primitive_cylinder_add(radius=0.13, depth=length, location=(x, 0, 0.75 + length / 2))
        parts.append(bpy.context.active_object)
    add.primitive_cylinder_add(radius=0.15, depth=1.0, location=(-1.0, 0, 0.1), rotation=(0, -0.9, 0))
    parts.append(bpy.context.active_object)
    add.primitive_cylinder_add(radius=0.4, depth=1.6, location=(0, 0, -1.3))
    parts.append(bpy.context.active_object)
    return _joined(parts, 0.04)


def _part():
    import bpy
    _empty_scene()
    bpy.ops.mesh.primitive_cube_add(size=2)
    slab = bpy.context.active_object
    slab.scale = (1.5, 1, 0.4)
    bpy.ops.object.transform_apply(scale=True)
    _modifier(slab, 'BEVEL', width=0.15, segments=3)
    bpy.ops.object.modifier_apply(modifier='bevel')
    bpy.ops.mesh.primitive_cylinder_add(radius=0.5, depth=1.2, location=(0.6, 0, 0.5))
    boss = bpy.context.active_object
    _modifier(slab, 'BOOLEAN', operation='UNION', object=boss)
    bpy.context.view_layer.objects.active = slab
    bpy.ops.object.modifier_apply(modifier='boolean')
    bpy.data.objects.remove(boss)
    _modifier(slab, 'REMESH', mode='VOXEL', voxel_size=0.04)
    return slab


def _suzanne(voxel):
    import bpy
    _empty_scene()
    bpy.ops.mesh.primitive_monkey_add()
    ob = bpy.context.active_object
    _modifier(ob, 'REMESH', mode='VOXEL', voxel_size=voxel)
    return ob


def _corpus(name):
    """The corpus mesh ``name`` as a Blender object (None when the corpus is missing)."""
    import bpy
    path = os.path.join(corpus_dir(), name + '.obj')
    if not os.path.exists(path):
        return None
    _empty_scene()
    bpy.ops.wm.obj_import(filepath=path)
    ob = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = ob
    return ob


def _decimated(ob, ratio):
    import bpy
    if ob is None:
        return None
    V, F = _arrays(ob)                         # the remesh, applied: the decimation works on it
    _empty_scene()
    me = bpy.data.meshes.new('mesh')
    me.from_pydata(V.tolist(), [], F.tolist())
    ob = bpy.data.objects.new('mesh', me)
    bpy.context.collection.objects.link(ob)
    bpy.context.view_layer.objects.active = ob
    _modifier(ob, 'DECIMATE', ratio=ratio)
    return ob


def load(name):
    """(V, F) of the Blender-made mesh ``name`` (one of ``NAMES``), or None (a corpus mesh missing)."""
    make = {'figure': _figure, 'hand': _hand, 'part': _part, 'suzvox': lambda: _suzanne(0.05),
            'figure-dec': lambda: _decimated(_figure(), 0.1),
            'suzvox-dec': lambda: _decimated(_suzanne(0.02), 0.05),
            'cow-dec': lambda: _decimated(_corpus('cow'), 0.2),
            'bunny-dec': lambda: _decimated(_corpus('stanford-bunny'), 0.05)}[name]
    ob = make()
    return None if ob is None else _arrays(ob)
