"""The compute step of a flatten run, without bpy: options, cancellation, one mesh's job, and the
worker-thread plumbing. Everything here runs in any thread; reading from and writing to Blender is in
``addon/read.py`` and ``addon/apply.py``.

All the UV work is one call of ``core.unwrap`` (disk, islands, holes, selections): this module never
looks at the mesh's topology."""
from dataclasses import dataclass, field
import hashlib
import threading
import time

import numpy as np

from ..core.atlas.unwrap import UnwrapResult, unwrap
from ..core.errors import ConformalError


def mesh_hash(md) -> str:
    """A short hash of the base mesh's positions and polygons (``MeshArrays``: ``V``,
    ``corner_verts``, ``sizes``), stored in the report so other tools can tell whether the mesh
    changed since it was flattened."""
    h = hashlib.blake2b(digest_size=12)
    for a in (md.V.astype(np.float32), md.corner_verts.astype(np.int32), md.sizes.astype(np.int32)):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


@dataclass
class FlattenOptions:
    """Everything a run needs besides the objects (the operator's properties)."""
    boundary: str = 'UNIFORM'
    fit: str = 'UNIT_SQUARE'
    bake: bool = True
    holes: str = 'AUTO'          # 'AUTO', 'FILL', 'CUT' or 'ERROR' (the operator's enum)
    keep_relative_scale: bool = True
    skip_bad_islands: bool = False
    packer: str = 'BLENDER'
    pack_shape: str = 'AABB'
    pack_rotate: bool = True
    margin: float = 0.001
    shared_layout: bool = False
    colormap: str = None
    max_faces: int = 5_000_000
    seams: str = 'KEEP'          # 'KEEP': the mesh's seams; 'AUTO': the core chooses seams through cones
    cones: int = 0               # with 'AUTO': a cone budget per part, 0 = as few as reach target_ratio
    target_ratio: float = 0.5

    @property
    def core_cones(self):
        """The core's ``cones`` argument: None (keep the seams), 'auto' or a budget."""
        if self.seams != 'AUTO':
            return None
        return 'auto' if self.cones == 0 else int(self.cones)

    @property
    def core_holes(self) -> str:
        """The core's hole mode: 'auto', 'fill', 'cut' or 'error'."""
        return self.holes.lower()


class Cancelled(Exception):
    """The run was cancelled (Esc or ``CancelToken.cancel``); nothing was written."""


class CancelToken:
    """Thread-safe cancellation flag, checked by ``compute_job`` at every progress report of the core
    (between its steps and between islands)."""

    def __init__(self):
        self._event = threading.Event()

    def cancel(self):
        self._event.set()

    @property
    def cancelled(self) -> bool:
        return self._event.is_set()

    def check(self):
        """Raise ``Cancelled`` if the run was cancelled."""
        if self._event.is_set():
            raise Cancelled("cancelled: nothing was written")


@dataclass
class MeshJob:
    """One mesh to flatten, as read in Object mode. ``md``: ``MeshArrays`` with triangles;
    ``faces`` (m,) bool: the triangles to flatten (None: all); ``seams`` (k,2) vertex pairs of the
    edges marked as seams; ``edges`` (e,2) all edges of the mesh (the core refuses loose ones on
    whole-mesh runs); ``counts`` (vertices, edges, corners, polygons) detect a mesh changed between
    read and apply; ``selection`` says what was flattened ('all', 'selected faces', ...)."""
    obj: object
    users: list
    md: object
    faces: np.ndarray
    seams: np.ndarray
    edges: np.ndarray
    counts: tuple
    selection: str

    @property
    def n_triangles(self) -> int:
        return int(len(self.md.tri_corners) if self.faces is None else self.faces.sum())


@dataclass
class JobResult:
    """What ``compute_job`` found for one ``MeshJob``: the core's ``UnwrapResult``, the flattened
    triangles ``tris`` (k,) and their corner UVs ``uv_tri`` (k,3,2) (the core's layout), and the
    compute time in seconds."""
    result: UnwrapResult
    tris: np.ndarray
    uv_tri: np.ndarray
    seconds: float = 0.0

    @property
    def report(self) -> dict:
        return self.result.report

    @property
    def islands(self) -> list:
        return self.result.islands


def compute_job(job: MeshJob, opts: FlattenOptions, progress=None,
                token: CancelToken | None = None) -> JobResult:
    """Flatten the faces of ``job`` with ``opts`` by one call of ``core.unwrap``. Pure numpy: no bpy,
    safe in a worker thread. ``progress(fraction, message)`` is called between steps; ``token`` is
    checked at each of them and raises ``Cancelled``. Raises ``ConformalError`` for bad input."""
    token = token or CancelToken()
    report = progress or (lambda f, msg: None)

    def step(f, msg):
        token.check()
        report(f, msg)

    t0 = time.perf_counter()
    step(0.0, 'preparing')
    md = job.md
    res = unwrap(md.V, md.F, seams=job.seams, faces=job.faces, tri_poly=md.tri_poly,
                 boundary=opts.boundary.lower(), holes=opts.core_holes, fit=opts.fit.lower(),
                 island_scale='true' if opts.keep_relative_scale else 'normalise', pack=True, margin=0.01,
                 on_error='skip' if opts.skip_bad_islands else 'raise', max_faces=opts.max_faces,
                 edges=job.edges, progress=step, cones=opts.core_cones, target_ratio=opts.target_ratio)
    tris = np.nonzero(res.flattened)[0]
    out = JobResult(result=res, tris=tris, uv_tri=res.uv_corner[tris])
    step(1.0, 'flattened')
    out.seconds = time.perf_counter() - t0
    return out


@dataclass
class Skipped:
    """An object left out with ``skip_bad_islands`` because none of its faces could be flattened."""
    name: str
    error: ConformalError


@dataclass
class Worker:
    """Computes a list of ``MeshJob`` (``compute``), synchronously or in a daemon thread (``start``,
    ``done``, ``cancel``); ``fraction`` and ``message`` follow the progress for a modal timer.
    With ``opts.skip_bad_islands`` an object that cannot be flattened at all is skipped (listed in
    ``skipped``) as long as another one can."""
    jobs: list
    opts: FlattenOptions
    token: CancelToken = field(default_factory=CancelToken)
    results: list = None
    skipped: list = field(default_factory=list)
    error: BaseException = None
    fraction: float = 0.0
    message: str = ''
    thread: threading.Thread = None

    @property
    def n_triangles(self) -> int:
        return sum(j.n_triangles for j in self.jobs or [])

    def compute(self, progress=None) -> list:
        """Compute every job (no bpy). Sets and returns ``results`` (None for a skipped job). Raises
        ``ConformalError`` or ``Cancelled``."""
        total = max(1, self.n_triangles)
        done = 0
        results, skipped = [], []
        several = len(self.jobs) > 1
        for job in self.jobs:
            base, span = done / total, job.n_triangles / total
            name = job.users[0]

            def sub(f, msg, base=base, span=span, name=name):
                self.fraction = base + span * f
                self.message = f"{name}: {msg}" if several else msg
                if progress is not None:
                    progress(self.fraction, self.message)

            try:
                results.append(compute_job(job, self.opts, sub, self.token))
            except ConformalError as exc:
                if several:
                    exc = exc.with_context(f"object {name!r}")
                if not (several and self.opts.skip_bad_islands):
                    raise exc from None
                skipped.append(Skipped(name, exc))
                results.append(None)
            done += job.n_triangles
        self.token.check()
        if all(r is None for r in results):
            raise skipped[0].error
        self.results, self.skipped = results, skipped
        return results

    def _run(self):
        try:
            self.compute()
        except Exception as exc:        # noqa: BLE001  (reported to the user by the modal operator)
            self.error = exc

    def start(self):
        """Run ``compute`` in a daemon worker thread."""
        self.thread = threading.Thread(target=self._run, name='conformal_flatten', daemon=True)
        self.thread.start()

    @property
    def done(self) -> bool:
        return self.thread is not None and not self.thread.is_alive()

    def cancel(self):
        """Ask the computation to stop at its next step; ``apply`` is then refused."""
        self.token.cancel()
