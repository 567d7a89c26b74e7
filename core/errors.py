"""The one exception type the core raises for bad input or a failed computation.

A ``ConformalError`` carries data, not only text:

- ``problem``: what is wrong, with counts and examples (always present);
- ``code``: a stable machine-readable kind (``CODES``), for scripts and tests;
- ``remedy``: a key of ``REMEDIES`` naming what the user can do, or None.

``str(exc)`` is the library and command-line wording: the problem, then the remedy in the core's own
terms (``REMEDIES[remedy]``). A front end words the remedy in its own terms from the key (the add-on:
``addon/wording.py``); no front end edits the message text.
"""

# code -> what kind of failure it is
CODES = {
    'invalid_input': "the arrays or options are malformed",
    'empty_mesh': "there is nothing to flatten",
    'too_large': "the mesh is over the size limit",
    'bad_coordinates': "some coordinates are NaN or infinite",
    'bad_topology': "the mesh's connectivity does not allow the requested map",
    'degenerate': "the geometry is numerically degenerate",
    'no_boundary': "a closed part cannot be flattened as a disk without seams",
    'holes': "a part has holes and the hole mode says to stop",
    'genus': "a part has handles that no seam cuts",
    'solve_failed': "a linear solve or an optimiser failed",
    'not_reached': "the fast marching front did not reach every vertex",
}

# remedy key -> the core's (library and command-line) wording of what to do
REMEDIES = {
    'fill_holes': "fill the holes (holes='fill', CLI --holes fill), cut them open (holes='cut'), or mark "
                  "a seam from each hole to the outer boundary",
    'mark_seams': "let the tool choose seams through cones (cones='auto', CLI --cones auto), mark seams "
                  "that cut it open (for example a seam loop around it plus a seam across each half), or use "
                  "sphere mode",
    'cut_handles': "mark seams that cut through every handle",
    'seam_handles': "let the tool choose seams through cones (cones='auto', CLI --cones auto), or mark seams "
                    "that cut it open and through every handle (sphere mode takes genus 0 only)",
    'use_sphere': "use sphere mode, or mark a seam that cuts it open",
    'use_disk': "use disk mode, or fill the holes",
    'raise_limit': "decimate it, or raise the size limit",
    'fix_coordinates': "fix or delete them",
    'clean_mesh': "clean the mesh (merge by distance, dissolve degenerate faces) and retry",
    'area_boundary': "try the 'area' boundary mode",
    'larger_grid': "increase the grid size",
}


class ConformalError(ValueError):
    """Bad input or an impossible request.

    ``ConformalError(problem, code='invalid_input', remedy=None)``: ``problem`` says what is wrong;
    ``remedy`` is a key of ``REMEDIES`` (None when the problem text already says what to do)."""

    def __init__(self, problem: str, code: str = 'invalid_input', remedy: str | None = None):
        if code not in CODES:
            raise KeyError(f"unknown ConformalError code {code!r}")
        if remedy is not None and remedy not in REMEDIES:
            raise KeyError(f"unknown ConformalError remedy {remedy!r}")
        self.problem, self.code, self.remedy = problem, code, remedy
        super().__init__(problem if remedy is None else f"{problem}: {REMEDIES[remedy]}")

    def with_context(self, prefix: str) -> 'ConformalError':
        """The same error with ``prefix`` (e.g. "island 2 of 3 (40 triangles)") before the problem."""
        return ConformalError(f"{prefix}: {self.problem}", self.code, self.remedy)
