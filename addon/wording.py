"""The add-on's wording of the core's remedies.

A ``ConformalError`` carries ``problem`` (what is wrong) and ``remedy`` (a key of
``core.errors.REMEDIES``). The core words remedies for the library and the command line; here each
key is worded with the add-on's own option names and Blender's menus. The message shown to the user
is ``f"{problem}: {remedy wording}"``; no message text is ever edited."""
from ..core.errors import REMEDIES

BLENDER_REMEDIES = {
    'fill_holes': "set Holes to Automatic, Fill or Cut, or mark a seam from each hole to the outer boundary "
                  "(Edge > Mark Seam)",
    'mark_seams': "set Seams to Automatic (Conformal sidebar: seams through cones), mark seams that cut "
                  "it open (Edge > Mark Seam), for example a loop around it and a seam across each half, or "
                  "use Sphere mode (Conformal sidebar)",
    'cut_handles': "mark seams that cut through every handle (Edge > Mark Seam)",
    'seam_handles': "set Seams to Automatic (Conformal sidebar: seams through cones), or mark seams that cut "
                    "it open and through every handle (Edge > Mark Seam); Sphere mode takes genus 0 only",
    'use_sphere': "use Sphere mode (Conformal sidebar), or mark a seam that cuts it open (Edge > Mark Seam)",
    'use_disk': "use Conformal Flatten (disk mode), or fill the holes (Mesh > Clean Up > Fill Holes)",
    'raise_limit': "decimate it (Decimate modifier, applied), or raise "
                   "Size Limit (triangles) in the add-on's preferences",
    'fix_coordinates': "fix or delete those vertices (Select > Select All by Trait)",
    'clean_mesh': "clean the mesh (Mesh > Clean Up > Merge by Distance, Degenerate Dissolve) and retry",
    'area_boundary': "try Boundary: Area",
    'larger_grid': "increase the Grid Size",
}
assert BLENDER_REMEDIES.keys() == REMEDIES.keys(), "every core remedy needs a Blender wording"


def remedy_text(key: str | None) -> str | None:
    """Blender wording of the remedy ``key`` (None -> None)."""
    return None if key is None else BLENDER_REMEDIES.get(key, REMEDIES.get(key))


def compose(problem: str, remedy: str | None) -> str:
    """``problem`` followed by the Blender wording of ``remedy`` (a key or None)."""
    text = remedy_text(remedy)
    return problem if text is None else f"{problem}: {text}"


def message(exc: BaseException) -> str:
    """The user-facing text of a ``ConformalError`` (or any exception: its ``str``)."""
    problem = getattr(exc, 'problem', None)
    if problem is None:
        return str(exc)
    return compose(problem, getattr(exc, 'remedy', None))


def island_error(rep: dict) -> str | None:
    """The user-facing text of a failed island's report (``error_problem``/``error_remedy`` keys set
    by the core), or None if the island did not fail."""
    if 'error' not in rep:
        return None
    if 'error_problem' in rep:
        return compose(rep['error_problem'], rep.get('error_remedy'))
    return rep['error']
