"""Which objects a flatten run works on, their modes, and reading each mesh into a ``job.MeshJob``
(main thread, bpy)."""
from contextlib import contextmanager

import bpy

from ..core.errors import ConformalError
from . import meshio
from .job import MeshJob


def target_objects(context):
    """The mesh objects to flatten, one per mesh (linked duplicates once), the active one first: in
    Edit mode the objects in Edit mode, otherwise the active object and the selected ones. Returns a
    list of (object, [names of all the target objects using its mesh]). Raises ``ConformalError``
    when there is no active object or no mesh among them."""
    active = getattr(context, 'active_object', None)
    if active is None:
        raise ConformalError("no active object: select a mesh object and make it active")
    view_layer = context.view_layer
    if active.mode == 'EDIT':
        cands = [active] + [o for o in view_layer.objects if o.mode == 'EDIT' and o is not active]
    else:
        cands = [active] + [o for o in (getattr(context, 'selected_objects', None) or [])
                            if o is not active]
    meshes = [o for o in cands if o.type == 'MESH']
    if not meshes:
        meshio.mesh_object(context, active)          # raises "... is a curve, not a mesh: ..."
        raise ConformalError("no mesh object is selected: select mesh objects")
    by_mesh = {}
    for o in meshes:
        meshio.mesh_object(context, o)               # raises for meshes linked from a library
        by_mesh.setdefault(o.data.as_pointer(), []).append(o)
    return [(objs[0], [o.name for o in objs]) for objs in by_mesh.values()]


@contextmanager
def _selected_only(context, objs):
    """For the body, exactly ``objs`` are selected and ``objs[0]`` is active (mode switches and UV
    operators act on the selected/active objects); the selection and the active object are put back
    afterwards."""
    view_layer = context.view_layer
    active = view_layer.objects.active
    selected = [o for o in view_layer.objects if o.select_get()]
    try:
        for o in selected:
            o.select_set(False)
        for o in objs:
            o.select_set(True)
        view_layer.objects.active = objs[0]
        yield
    finally:
        for o in objs:
            o.select_set(False)
        for o in selected:
            o.select_set(True)
        view_layer.objects.active = active


def _enter_mode(context, objs, mode):
    """Put exactly ``objs`` (all in Object mode) into ``mode``."""
    with _selected_only(context, objs):
        bpy.ops.object.mode_set(mode=mode)


@contextmanager
def in_edit_mode(context, objs):
    """For the body, exactly ``objs`` are in Edit mode, selected, ``objs[0]`` active; back to Object
    mode afterwards."""
    with _selected_only(context, objs):
        bpy.ops.object.mode_set(mode='EDIT')
        try:
            yield
        finally:
            bpy.ops.object.mode_set(mode='OBJECT')


@contextmanager
def objects_in_object_mode(context, obj):
    """Run the body with every object that shares ``obj``'s mode in Object mode (leaving Edit mode
    writes the edit meshes), then put exactly those objects back into their mode, also on errors."""
    mode = obj.mode
    if mode == 'OBJECT':
        yield
        return
    in_mode = [obj] + [o for o in context.view_layer.objects if o.mode == mode and o is not obj]
    meshio._set_mode(obj, 'OBJECT')
    if obj.mode != 'OBJECT':                 # the override did not reach it: use the view layer
        _enter_mode(context, [obj], 'OBJECT')
    try:
        yield
    finally:
        alive = []
        for o in in_mode:
            try:
                if o.mode == 'OBJECT' and o.name in context.view_layer.objects:
                    alive.append(o)
            except ReferenceError:
                pass
        if alive:
            _enter_mode(context, alive, mode)


def read_job(obj, users=None, use_selection=None) -> MeshJob:
    """Read mesh object ``obj`` (in Object mode) into a ``MeshJob``. ``use_selection``: only the
    selected faces (default: when ``obj`` was in Edit mode; pass it explicitly inside
    ``objects_in_object_mode``); no face selected (or all of them) means the whole mesh. Raises
    ``ConformalError`` (no faces)."""
    me = obj.data
    md = meshio.read_mesh(me)
    E = meshio.read_edges(me)
    sel = meshio.read_selection(me, 'FACE') if use_selection else None
    selection, faces = 'all', None
    if sel is not None:
        if not sel.any():
            selection = 'all (no face selected)'
        elif not sel.all():
            selection, faces = 'selected faces', sel[md.tri_poly]
    return MeshJob(obj=obj, users=list(users or [obj.name]), md=md, faces=faces,
                   seams=E[meshio.read_seams(me)], edges=E,
                   counts=(len(me.vertices), len(me.edges), len(me.loops), len(me.polygons)),
                   selection=selection)
