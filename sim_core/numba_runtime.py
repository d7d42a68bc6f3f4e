"""numba's process-wide settings that sim_core relies on, and the lock that goes with them.

Importing this module fixes them; every module that defines or launches a parallel
(``parallel=True``, ``prange``) kernel imports it: :mod:`sim_core.materials.kernels` (the batch
wrappers of the material classes' numpy API) and :mod:`sim_core.render.kernels`
(``camera_rays``, the renderer's ground truth). The renderer's per-ray kernels are serial and
``nogil`` and need neither.

Threading layer: ``workqueue``
    numba's default choice, OpenMP or TBB, keeps its worker threads spinning for a while after
    each parallel region. Between two parallel kernels those spinning threads starve Embree's
    worker threads and numpy (measured by the renderer: 2x slower frames on 2 cores). The
    ``workqueue`` layer parks its threads instead. A process's layer is fixed by the first
    parallel kernel it *runs*, which may be any of them (e.g. Hapke's constructor evaluates a
    batch), so the choice is made at import, before any of them can run. An explicit choice
    (``NUMBA_THREADING_LAYER`` in the environment) is left alone.

:data:`PARALLEL_KERNEL_LOCK`
    The ``workqueue`` layer is not thread-safe: when two threads launch parallel kernels at the
    same time it aborts the whole process ("Numba workqueue threading layer is terminating:
    Concurrent access has been detected."; no Python exception to catch). Every call of a
    parallel kernel in sim_core holds this lock, so a service or a simulated camera may render
    and evaluate materials from several threads (``tests/sim_core/render/test_threads.py``). It
    is re-entrant so that a caller holding it may call code that takes it again.
"""

from __future__ import annotations

import threading

import numba

if numba.config.THREADING_LAYER == "default":
    numba.config.THREADING_LAYER = "workqueue"

#: held around every call of a parallel numba kernel in this process (see the module docstring)
PARALLEL_KERNEL_LOCK = threading.RLock()
