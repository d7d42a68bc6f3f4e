"""Ray casting on Intel Embree, batched and split across threads.

Two ways to reach Embree, chosen per tracer (:attr:`RayTracer.backend`):

- ``"binding"`` (the default where it loads): :mod:`sim_core.embree_binding`, our own binding of
  the ``libembree4`` that embreex ships. Its queries are compiled numba functions that trace
  packets of rays (:class:`PacketWidths`), and the renderer calls them from inside one kernel
  per chunk (:attr:`RayTracer.kernel_scene`), with no Python between bounces.
- ``"embreex"``: embreex's own scene and single-ray loop, the fallback where the binding cannot
  load (:attr:`RayTracer.fallback_reason` says why) or when asked for (``backend="embreex"`` or
  the environment variable ``TOFTWIN_EMBREE=embreex``).

Both give bit-identical answers (same rays, same geometry buffers, same robust flag), so a
frame does not depend on the backend (``tests/sim_core/test_embree_binding.py``).

Embree works in float32. To keep precision for scenes far from the world origin, geometry and
rays are expressed relative to ``origin_m`` (the camera centre): a scene 1e6 m from the origin
then traces as precisely as one at the origin.

Either backend's batch query releases the GIL for its whole loop, so a batch split in
contiguous chunks over a thread pool runs on all cores; each ray's answer does not depend on
the chunking, so results are identical for any number of threads. The renderer instead runs
whole chunks of its work on the tracer's pool (:meth:`RayTracer.submit`) and queries Embree
from those worker threads directly (:attr:`RayTracer.kernel_scene` or the ``*_here`` methods).

Time inside Embree is counted per thread (:attr:`TraceStats.seconds` is thread-seconds), so
``seconds / (wall time x threads)`` is the share of the machine's capacity spent in Embree,
whichever way the queries were spread.
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from sim_core import embree_binding

#: below this many rays per thread, splitting costs more than it gains
#: (an embreex call costs ~1-3 us of overhead; its throughput is flat from ~10k rays a call)
MIN_RAYS_PER_THREAD = 16_384
#: environment variable that forces a backend for every tracer of the process
BACKEND_ENV = "TOFTWIN_EMBREE"
BACKENDS = ("auto", "binding", "embreex")


@dataclass(frozen=True)
class PacketWidths:
    """Rays per Embree query call of the binding backend, by kind of ray (1 = single rays).

    Packets pay where a packet's rays traverse the same nodes: shadow rays all converge on the
    camera's co-located source, camera rays all leave its centre, and a chunk's bounce rays
    leave neighbouring pixels' hit points (random directions, but nearby origins). Measured on
    a chunk's real rays (corner and satellite, 64 spp, AVX2, ns per ray, width 1 -> 8): camera
    84-99 -> 58-72, bounce 66-130 -> 35-76, shadow 38-132 -> 16-45 (random rays from scattered
    origins, by contrast, were 20 % slower in closest-hit packets on the corner).
    ``None`` means the widest the device runs natively.

    ``coherent`` is Embree's traversal hint per kind (``RTC_RAY_QUERY_FLAG_COHERENT``; answers
    are the same either way): on for camera and shadow rays, off for bounce rays.
    """

    camera: int | None = None
    bounce: int | None = None
    shadow: int | None = None
    coherent: tuple[bool, bool, bool] = (True, False, True)

    def resolved(self) -> tuple[int, int, int]:
        """(camera, bounce, shadow) widths, each checked against the device.

        Raises
        ------
        sim_core.embree_binding.UnsupportedPacketWidthError
            For a width the device does not run natively.
        """
        return tuple(
            embree_binding.widest() if w is None else embree_binding.check_width(w)
            for w in (self.camera, self.bounce, self.shadow)
        )


@dataclass
class TraceStats:
    """Counters of the work done by a :class:`RayTracer`.

    ``seconds`` is thread-seconds inside Embree queries: summed over the threads that ran them.
    """

    rays: int = 0
    seconds: float = 0.0

    def snapshot(self) -> TraceStats:
        return TraceStats(self.rays, self.seconds)


class RayTracer:
    """Closest-hit and occlusion queries against a fixed triangle set.

    Parameters
    ----------
    triangles_m : (n, 3, 3) float64
        World-frame triangles.
    origin_m : (3,) float64
        Origin of the render frame; every ray of this tracer is given relative to it.
    threads : int, optional
        Worker threads: they split large batches, and the renderer runs its chunks on them
        (default: all cores).
    robust : bool
        Embree's robust mode (``RTC_SCENE_FLAG_ROBUST``): conservative traversal and watertight
        triangle tests, exact even for rays aimed at a shared edge. Off by default, as in
        Mitsuba 3 (``RTC_SCENE_FLAG_NONE``): on the frames we render it changes nothing we can
        find and costs 1.3-1.6x the Embree time (issue 30). Measured: of 9.8 M jittered camera
        rays (256 spp) of the corner and of the satellite ground test, none missed in the fast
        mode that hit in the robust one, and 1 and 3 met the neighbouring triangle of the same
        edge; only rays aimed exactly at a shared edge leak (2e-3 of them on the corner's
        seams), a set of measure zero in a render. ``tests/sim_core/test_tracing_modes.py``
        keeps those figures.
    backend : "auto", "binding" or "embreex"
        How to reach Embree (see the module docstring). "auto" (default; overridden by the
        environment variable ``TOFTWIN_EMBREE``) takes the binding where it loads, else
        embreex; "binding" raises :class:`sim_core.embree_binding.EmbreeBindingError` where it
        cannot load.
    widths : PacketWidths, optional
        Packet widths of the binding backend (default :class:`PacketWidths`); a width the
        device does not support natively raises
        :class:`sim_core.embree_binding.UnsupportedPacketWidthError`.
    """

    def __init__(
        self,
        triangles_m: np.ndarray,
        origin_m: np.ndarray,
        threads: int | None = None,
        robust: bool = False,
        backend: str = "auto",
        widths: PacketWidths | None = None,
    ) -> None:
        self.origin_m = np.asarray(origin_m, dtype=np.float64)
        self.n_triangles = int(triangles_m.shape[0])
        self.threads = max(1, threads or os.cpu_count() or 1)
        self.stats = TraceStats()
        self._stats_lock = threading.Lock()
        rel = (np.asarray(triangles_m, dtype=np.float64) - self.origin_m).astype(np.float32)
        self.backend, self.fallback_reason = _choose_backend(backend)
        #: (camera, bounce, shadow) packet widths; all 1 on the embreex backend
        self.widths = (1, 1, 1)
        #: (camera, bounce, shadow) Embree coherence hints (binding backend only)
        self.coherent = (False, False, False)
        self._scene = self._binding_scene = None
        if self.backend == "binding":
            packets = widths or PacketWidths()
            self.widths = packets.resolved()
            self.coherent = tuple(bool(c) for c in packets.coherent)
            self._binding_scene = embree_binding.EmbreeScene(rel, robust=robust)
        else:
            self._scene = rtcs.EmbreeScene(robust=robust)
            if self.n_triangles:
                self._mesh = TriangleMesh(self._scene, rel)
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    @property
    def kernel_scene(self) -> int | None:
        """The binding's scene handle for compiled kernels (:mod:`sim_core.embree_binding`
        queries), or None on the embreex backend."""
        return None if self._binding_scene is None else self._binding_scene.handle

    def count(self, rays: int, seconds: float) -> None:
        """Add queries made elsewhere (a compiled kernel given :attr:`kernel_scene`)."""
        self._count(rays, seconds)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    def __enter__(self) -> RayTracer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def submit(self, fn, /, *args) -> Future:
        """Run ``fn(*args)`` on this tracer's thread pool (only when ``threads > 1``; with one
        thread callers run their work themselves).

        ``fn`` must query Embree only through the ``*_here`` methods: waiting for the pool from
        inside the pool could deadlock.
        """
        if self._pool is None:
            raise RuntimeError("submit: this tracer has one thread and no pool")
        return self._pool.submit(fn, *args)

    def _count(self, rays: int, seconds: float) -> None:
        with self._stats_lock:
            self.stats.rays += rays
            self.stats.seconds += seconds

    def _dispatch(self, fn, n: int):
        """Run ``fn(start, stop)`` over [0, n) in contiguous chunks on the pool."""

        def timed(a: int, b: int) -> float:
            t0 = time.perf_counter()
            fn(a, b)
            return time.perf_counter() - t0

        k = min(self.threads, max(1, n // MIN_RAYS_PER_THREAD))
        if k <= 1 or self._pool is None:
            seconds = timed(0, n)
        else:
            edges = np.linspace(0, n, k + 1).astype(np.int64)
            futures = [self._pool.submit(timed, a, b) for a, b in pairwise(edges.tolist())]
            seconds = sum(f.result() for f in futures)
        self._count(n, seconds)

    def intersect(
        self, origins_rel: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Closest hits of rays given in the render frame.

        Parameters
        ----------
        origins_rel : (m, 3) float
            Ray origins relative to ``origin_m``.
        directions : (m, 3) float
            Unit directions.

        Returns
        -------
        t_m : (m,) float64
            Hit distance [m]; ``inf`` where the ray escapes.
        prim : (m,) int64
            Triangle index; -1 where the ray escapes.
        """
        tfar, pid = self.intersect32(
            np.ascontiguousarray(origins_rel, dtype=np.float32),
            np.ascontiguousarray(directions, dtype=np.float32),
        )
        hit = pid >= 0
        return np.where(hit, tfar.astype(np.float64), np.inf), pid.astype(np.int64)

    def intersect32(self, o32: np.ndarray, d32: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest hits of float32 render-frame rays, without conversions.

        Returns ``tfar`` (float32, meaningless where missed) and ``prim`` (int32, -1 = miss).
        """
        m = o32.shape[0]
        tfar = np.full(m, np.finfo(np.float32).max, dtype=np.float32)
        pid = np.full(m, -1, dtype=np.int32)
        if m == 0 or self.n_triangles == 0:
            self._count(m, 0.0)
            return tfar, pid

        def work(a: int, b: int) -> None:
            tfar[a:b], pid[a:b] = self._closest(o32[a:b], d32[a:b])

        self._dispatch(work, m)
        return tfar, pid

    def _closest(self, o32: np.ndarray, d32: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One closest-hit batch: (tfar float32, primID int32 with -1 = miss)."""
        if self._binding_scene is not None:
            m = o32.shape[0]
            tfar = np.empty(m, dtype=np.float32)
            prim = np.empty(m, dtype=np.int32)
            embree_binding.intersect(
                self._binding_scene.handle, o32, d32, self.widths[0],
                embree_binding.packet_buffer(), tfar, prim, np.zeros(2),
            )
            return tfar, prim
        # embreex fills ``dists`` in place only for query="DISTANCE" (which returns no
        # primitive ids); the full output dict is the one call that gives both.
        res = self._scene.run(o32, d32, output=1)
        return res["tfar"], res["primID"]

    def intersect_here(self, o32: np.ndarray, d32: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`intersect32` on the calling thread (for work running on :meth:`submit`)."""
        m = o32.shape[0]
        if m == 0 or self.n_triangles == 0:
            return self.intersect32(o32, d32)  # nothing to trace: its empty answer
        t0 = time.perf_counter()
        hits = self._closest(o32, d32)
        self._count(m, time.perf_counter() - t0)
        return hits

    def occluded_here(self, o32: np.ndarray, d32: np.ndarray, tmax32: np.ndarray) -> np.ndarray:
        """Embree's occlusion answers on the calling thread: 0 = blocked, -1 = free.

        ``tmax32`` is overwritten.
        """
        m = o32.shape[0]
        if m == 0 or self.n_triangles == 0:
            self._count(m, 0.0)
            return np.full(m, -1, dtype=np.int32)
        t0 = time.perf_counter()
        if self._binding_scene is not None:
            res = np.empty(m, dtype=np.int32)
            embree_binding.occluded(
                self._binding_scene.handle, o32, d32, tmax32, self.widths[2],
                embree_binding.packet_buffer(), res, np.zeros(2),
            )
        else:
            res = self._scene.run(o32, d32, dists=tmax32, query="OCCLUDED")
        self._count(m, time.perf_counter() - t0)
        return res


def _choose_backend(requested: str) -> tuple[str, str | None]:
    """(backend, why the binding is not used or None) for a tracer asked for ``requested``."""
    if requested == "auto":
        requested = os.environ.get(BACKEND_ENV, "auto") or "auto"
    if requested not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {requested!r}")
    if requested == "embreex":
        return "embreex", "embreex requested"
    try:
        embree_binding.device()  # raises where the library did not load or has no device
    except embree_binding.EmbreeBindingError as exc:
        if requested == "binding":
            raise
        return "embreex", f"binding unavailable: {exc}"
    return "binding", None
