"""Our own binding of Intel Embree 4: set-up through ctypes, ray queries from numba kernels.

Why: embreex reaches Embree one ray at a time from Python, so a path tracer built on it pays a
Python round trip per bounce and cannot use Embree's ray *packets*. Shadow rays towards the
camera's co-located source are coherent, and a packet of them costs Embree 2-3x less per ray
than single rays (issue 16). This module is the one home of the Embree C interface in the
project: :class:`sim_core.tracing.RayTracer` decides whether to use it or embreex's tracer (the
fallback, kept for machines where this binding cannot load).

What it binds
-------------
- The library: the very ``libembree4`` that embreex ships and has loaded (found in the
  process's memory map after importing embreex, else beside embreex's package). embreex stays
  the dependency that carries it; no second copy of Embree is loaded.
- Set-up calls through ctypes (:class:`EmbreeScene`): a process-wide device, a scene (robust
  flag on request), one triangle geometry filled with ``rtcSetNewGeometryBuffer`` exactly as
  embreex's ``TriangleMesh`` fills its own (unshared float32 vertices with a 16-byte stride,
  indices 3i, 3i+1, 3i+2), commit, and ``rtcGetDeviceError`` after every step.
- The ray queries ``rtcIntersect1/4/8/16`` and ``rtcOccluded1/4/8/16`` declared to numba as
  external functions whose addresses are given to LLVM at import (``llvmlite.binding.add_symbol``),
  so the kernels that call them keep ``cache=True``: a cached kernel refers to the symbol by
  name and is linked against this process's address when loaded.

Rays are given exactly as embreex gives them (``tnear`` 0, ``tfar`` 1e37 for closest hits or the
caller's ``tmax`` for occlusion, mask all ones, time 0, flags 0; the query arguments carry a
coherence hint only), so the answers are bit-identical to embreex's (tests:
``tests/sim_core/test_embree_binding.py``).

Query arguments
---------------
Every query is given an ``RTCIntersectArguments`` / ``RTCOccludedArguments`` (the same 32-byte
layout: flags, feature mask, then null context, filter and intersect pointers), kept in the
packet buffer. Its flags say whether the packet's rays are coherent (camera rays from one
centre, shadow rays converging on the camera's source: ``RTC_RAY_QUERY_FLAG_COHERENT``) or not
(bounce rays: ``RTC_RAY_QUERY_FLAG_INCOHERENT``, Embree's default). The flag changes how Embree
traverses a packet, never its answer.

Packets
-------
A width-``W`` packet (Embree 4 ``RTCRayHitW``/``RTCRayW``) is structure-of-arrays: field ``k`` of
lane ``j`` is the 32-bit word ``k * W + j``, ray fields 0-11 (org_x, org_y, org_z, tnear, dir_x,
dir_y, dir_z, time, tfar, mask, id, flags), hit fields 12-20 (Ng_x, Ng_y, Ng_z, u, v, primID,
geomID, instID, instPrimID). The single-ray ``RTCRayHit`` is the same formula with ``W = 1``
(its hit part starts on a 16-byte boundary, word 12). Packets and their ``valid`` masks (-1
valid, 0 invalid) are 64-byte aligned. A packet width the device does not support natively
(``RTC_DEVICE_PROPERTY_NATIVE_RAY{4,8,16}_SUPPORTED``) is refused by :func:`check_width`; on an
AVX2 machine that is 16.

The C prototypes take pointers; they are declared to numba as ``uintp`` (64-bit) integers,
which the x86-64 and AArch64 calling conventions pass exactly like pointers (checked at import).
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
import threading
from pathlib import Path

import numpy as np
from llvmlite import binding as llvm_binding
from numba import njit, types

#: Embree's marker of "no geometry / no primitive" in RTCHit (RTC_INVALID_GEOMETRY_ID)
RTC_INVALID_GEOMETRY_ID = 0xFFFFFFFF
#: the ``tfar`` embreex gives closest-hit rays, kept for bit-identical answers
TFAR_CLOSEST = np.float32(1e37)
#: packet widths Embree has entry points for
WIDTHS = (1, 4, 8, 16)
#: 32-bit words of one packet buffer: 21 fields x 16 lanes rounded up, then the valid mask
_VALID_WORD = 384  # byte 1536: 64-byte aligned
#: the query arguments (RTCIntersectArguments = RTCOccludedArguments, 32 bytes, 8 words; 16
#: reserved should a build add RTC_MIN_WIDTH's float): incoherent rays, then coherent ones
_ARGS_WORD_INCOHERENT = 400  # byte 1600, 64-byte aligned
_ARGS_WORD_COHERENT = 416  # byte 1664
_BUF_WORDS = 432
#: RTCRayQueryFlags and RTCFeatureFlags values (rtcore_common.h)
_QUERY_FLAG_INCOHERENT = 0
_QUERY_FLAG_COHERENT = 1
_FEATURE_FLAG_ALL = 0xFFFFFFFF
#: RTCDeviceProperty values (rtcore_device.h)
_PROP_VERSION = 0
_PROP_NATIVE = {4: 32, 8: 33, 16: 34}
#: RTCSceneFlags, RTCGeometryType, RTCBufferType, RTCFormat values (rtcore_*.h)
_SCENE_FLAG_ROBUST = 1 << 2
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX = 0
_BUFFER_TYPE_VERTEX = 1
_FORMAT_UINT3 = 0x5003
_FORMAT_FLOAT3 = 0x9003
_ERRORS = {0: "none", 1: "unknown", 2: "invalid argument", 3: "invalid operation",
           4: "out of memory", 5: "unsupported CPU", 6: "cancelled", 7: "level zero raytracing"}


class EmbreeBindingError(RuntimeError):
    """The binding cannot be used (library not found, a call failed, a width unsupported)."""


class UnsupportedPacketWidthError(EmbreeBindingError, ValueError):
    """A packet width the device does not support natively was requested."""


# -------------------------------------------------------------------------------------------
# Finding and loading the library
# -------------------------------------------------------------------------------------------
def _loaded_embree_paths() -> list[str]:
    """Paths of ``libembree4`` mapped into this process (Linux ``/proc/self/maps``)."""
    try:
        text = Path("/proc/self/maps").read_text()
    except OSError:
        return []
    paths = {line.split(None, 5)[-1].strip() for line in text.splitlines()
             if "libembree4" in line and "/" in line}
    return sorted(p for p in paths if os.path.isfile(p))


def find_library() -> str:
    """Path of the ``libembree4`` that embreex uses.

    First the copy embreex has already loaded (after importing its scene module), so that one
    library serves both; else a copy shipped beside embreex's package (``embreex.libs`` of a
    manylinux wheel, ``.dylibs`` of a macOS one, or the package itself).

    Raises
    ------
    EmbreeBindingError
        If embreex is not installed or no such library is found.
    """
    try:
        import embreex
        from embreex import rtcore_scene  # noqa: F401  (loads libembree4 into the process)
    except ImportError as exc:
        raise EmbreeBindingError(f"embreex is not importable: {exc}") from exc
    pkg = Path(embreex.__file__).resolve().parent
    loaded = _loaded_embree_paths()
    # embreex's own copy first, should another libembree4 be mapped too
    ours = [p for p in loaded if Path(p).resolve().is_relative_to(pkg.parent)]
    if ours or loaded:
        return (ours or loaded)[0]
    for folder in (pkg.parent / "embreex.libs", pkg / ".dylibs", pkg):
        found = sorted(glob.glob(str(folder / "libembree4*")))
        if found:
            return found[0]
    raise EmbreeBindingError(f"no libembree4 loaded by embreex nor found beside {pkg}")


def _declare(lib: ctypes.CDLL) -> None:
    """ctypes prototypes of the set-up calls."""
    vp, u32, sz = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
    protos = {
        "rtcNewDevice": (vp, [ctypes.c_char_p]),
        "rtcGetDeviceError": (ctypes.c_int, [vp]),
        "rtcGetDeviceProperty": (ctypes.c_ssize_t, [vp, ctypes.c_int]),
        "rtcNewScene": (vp, [vp]),
        "rtcSetSceneFlags": (None, [vp, ctypes.c_int]),
        "rtcNewGeometry": (vp, [vp, ctypes.c_int]),
        "rtcSetNewGeometryBuffer": (vp, [vp, ctypes.c_int, u32, ctypes.c_int, sz, sz]),
        "rtcCommitGeometry": (None, [vp]),
        "rtcAttachGeometry": (u32, [vp, vp]),
        "rtcReleaseGeometry": (None, [vp]),
        "rtcCommitScene": (None, [vp]),
        "rtcReleaseScene": (None, [vp]),
    }
    for name, (res, args) in protos.items():
        fn = getattr(lib, name)
        fn.restype = res
        fn.argtypes = args


#: the C query functions, by name: (numba signature); pointers as uintp (see the docstring)
_P = types.uintp
_QUERY_SIGS = {
    "rtcIntersect1": types.void(_P, _P, _P),
    "rtcOccluded1": types.void(_P, _P, _P),
    **{f"rtc{q}{w}": types.void(_P, _P, _P, _P)
       for q in ("Intersect", "Occluded") for w in (4, 8, 16)},
}
#: clock_gettime(CLOCK_MONOTONIC, struct timespec*) of the C library, to time queries in kernels
_CLOCK_MONOTONIC = 1
_clock_gettime = types.ExternalFunction("clock_gettime", types.intc(types.intc, _P))


def _load() -> tuple[ctypes.CDLL | None, str]:
    """Load the library and give its query functions to LLVM; (library, "") or (None, why)."""
    if ctypes.sizeof(ctypes.c_void_p) != np.dtype(np.uintp).itemsize:
        return None, "pointers are not the size of uintp on this platform"
    try:
        path = find_library()
        lib = ctypes.CDLL(path)
        _declare(lib)
        for name in _QUERY_SIGS:
            llvm_binding.add_symbol(name, ctypes.cast(getattr(lib, name), ctypes.c_void_p).value)
        libc = ctypes.CDLL(None)
        llvm_binding.add_symbol(
            "clock_gettime", ctypes.cast(libc.clock_gettime, ctypes.c_void_p).value
        )
    except (OSError, AttributeError, EmbreeBindingError) as exc:
        return None, f"{type(exc).__name__}: {exc}"
    return lib, ""


_LIB, UNAVAILABLE_REASON = _load()
#: whether this binding can be used in this process (else :data:`UNAVAILABLE_REASON` says why)
AVAILABLE = _LIB is not None
_DEVICE: int | None = None
_DEVICE_LOCK = threading.Lock()


def _lib() -> ctypes.CDLL:
    if _LIB is None:
        raise EmbreeBindingError(f"the Embree binding is unavailable: {UNAVAILABLE_REASON}")
    return _LIB


def _check(what: str) -> None:
    """Raise if the device recorded an error (``rtcGetDeviceError`` clears it)."""
    code = _lib().rtcGetDeviceError(device())
    if code != 0:
        raise EmbreeBindingError(f"Embree {what} failed: {_ERRORS.get(code, code)} ({code})")


def device() -> int:
    """The process-wide Embree device (created on first use, kept for the process's life)."""
    global _DEVICE
    with _DEVICE_LOCK:
        if _DEVICE is None:
            dev = _lib().rtcNewDevice(None)
            if not dev:
                raise EmbreeBindingError("rtcNewDevice returned no device (unsupported CPU?)")
            _DEVICE = int(dev)
        return _DEVICE


def version() -> int:
    """Embree's version as MAJOR*10000 + MINOR*100 + PATCH (e.g. 40400 for 4.4.0)."""
    return int(_lib().rtcGetDeviceProperty(device(), _PROP_VERSION))


def supported_widths() -> tuple[int, ...]:
    """Packet widths this device runs natively, 1 (single rays) always included."""
    lib, dev = _lib(), device()
    return (1, *(w for w, p in _PROP_NATIVE.items() if lib.rtcGetDeviceProperty(dev, p) == 1))


def check_width(width: int) -> int:
    """``width`` if the device supports packets of that many rays natively, else a clear error.

    Raises
    ------
    UnsupportedPacketWidthError
        For a width Embree has no entry point for, or one this CPU does not run natively
        (calling it would be emulated or refused by Embree).
    """
    ok = supported_widths()
    if width not in ok:
        raise UnsupportedPacketWidthError(
            f"packet width {width} is not supported by Embree {version()} on this CPU; "
            f"supported widths: {', '.join(map(str, ok))}"
        )
    return int(width)


def widest() -> int:
    """The widest packet the device supports natively."""
    return max(supported_widths())


class EmbreeScene:
    """A committed Embree scene of one triangle geometry, built through this binding.

    Parameters
    ----------
    triangles32 : (n, 3, 3) float32
        Triangles in the frame the rays will be given in (the render frame: world minus the
        tracer's origin, see :mod:`sim_core.tracing`).
    robust : bool
        Embree's robust mode (``RTC_SCENE_FLAG_ROBUST``): watertight at shared edges, 1.3-1.6x
        the query time on the corner; off by default, as the renderer's tracer (why:
        :class:`sim_core.tracing.RayTracer`).
    """

    def __init__(self, triangles32: np.ndarray, robust: bool = False) -> None:
        lib = _lib()
        tris = np.ascontiguousarray(triangles32, dtype=np.float32).reshape(-1, 3, 3)
        n = tris.shape[0]
        self._scene = lib.rtcNewScene(device())
        _check("rtcNewScene")
        lib.rtcSetSceneFlags(self._scene, _SCENE_FLAG_ROBUST if robust else 0)
        if n:
            geom = lib.rtcNewGeometry(device(), _GEOMETRY_TYPE_TRIANGLE)
            _check("rtcNewGeometry")
            vptr = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_VERTEX, 0, _FORMAT_FLOAT3,
                                               16, 3 * n)
            iptr = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_INDEX, 0, _FORMAT_UINT3,
                                               12, n)
            _check("rtcSetNewGeometryBuffer")
            # the same buffers as embreex's TriangleMesh: x, y, z, pad per vertex; 3i..3i+2
            verts = np.ctypeslib.as_array(ctypes.cast(vptr, ctypes.POINTER(ctypes.c_float)),
                                          shape=(3 * n, 4))
            verts[:, :3] = tris.reshape(3 * n, 3)
            verts[:, 3] = 0.0
            idx = np.ctypeslib.as_array(ctypes.cast(iptr, ctypes.POINTER(ctypes.c_uint32)),
                                        shape=(n, 3))
            idx[:] = np.arange(3 * n, dtype=np.uint32).reshape(n, 3)
            lib.rtcCommitGeometry(geom)
            lib.rtcAttachGeometry(self._scene, geom)
            lib.rtcReleaseGeometry(geom)
            _check("geometry set-up")
        lib.rtcCommitScene(self._scene)
        _check("rtcCommitScene")
        self.n_triangles = n

    @property
    def handle(self) -> int:
        """The ``RTCScene`` pointer, as the query kernels take it (0 once released)."""
        return int(self._scene or 0)

    def close(self) -> None:
        """Release the scene (the kernels must not be given its handle afterwards)."""
        if self._scene:
            _lib().rtcReleaseScene(self._scene)
            self._scene = None

    def __del__(self) -> None:
        with contextlib.suppress(Exception):  # at interpreter shutdown nothing is left
            self.close()


# -------------------------------------------------------------------------------------------
# Queries, compiled
# -------------------------------------------------------------------------------------------
_intersect1 = types.ExternalFunction("rtcIntersect1", _QUERY_SIGS["rtcIntersect1"])
_occluded1 = types.ExternalFunction("rtcOccluded1", _QUERY_SIGS["rtcOccluded1"])
_intersect4 = types.ExternalFunction("rtcIntersect4", _QUERY_SIGS["rtcIntersect4"])
_occluded4 = types.ExternalFunction("rtcOccluded4", _QUERY_SIGS["rtcOccluded4"])
_intersect8 = types.ExternalFunction("rtcIntersect8", _QUERY_SIGS["rtcIntersect8"])
_occluded8 = types.ExternalFunction("rtcOccluded8", _QUERY_SIGS["rtcOccluded8"])
_intersect16 = types.ExternalFunction("rtcIntersect16", _QUERY_SIGS["rtcIntersect16"])
_occluded16 = types.ExternalFunction("rtcOccluded16", _QUERY_SIGS["rtcOccluded16"])

_SERIAL = {"cache": True, "nogil": True, "error_model": "numpy"}


def packet_buffer() -> np.ndarray:
    """A zeroed, 64-byte aligned scratch buffer of 32-bit words for one packet (any width).

    One per thread: the query kernels write rays into it; it also holds the query arguments
    (see "Query arguments" in the module docstring).
    """
    raw = np.zeros(_BUF_WORDS + 16, dtype=np.uint32)
    skip = (-raw.ctypes.data % 64) // 4
    buf = raw[skip: skip + _BUF_WORDS]
    for word, flag in ((_ARGS_WORD_INCOHERENT, _QUERY_FLAG_INCOHERENT),
                       (_ARGS_WORD_COHERENT, _QUERY_FLAG_COHERENT)):
        buf[word] = flag
        buf[word + 1] = _FEATURE_FLAG_ALL  # context, filter, intersect: null (zeroed words)
    return buf


@njit(cache=True, nogil=True)
def now_s():
    """Monotonic clock [s] inside compiled code (C ``clock_gettime``), for query timing."""
    ts = np.zeros(2, dtype=np.int64)
    _clock_gettime(_CLOCK_MONOTONIC, ts.ctypes.data)
    return ts[0] + 1e-9 * ts[1]


@njit(cache=True, nogil=True, inline="always")
def _prepare_packet(buf, w):
    """The fields that are the same for every ray of a call into the width-``w`` packet in
    ``buf``: ``tnear`` 0, ``time`` 0, mask all ones, ``id`` and ``flags`` 0 (Embree reads them
    and never writes them), and every lane valid. Once per :func:`intersect` or
    :func:`occluded` call: a call's packets all have its width."""
    f = buf.view(np.float32)
    valid = buf[_VALID_WORD: _VALID_WORD + 16].view(np.int32)
    for j in range(w):
        f[3 * w + j] = 0.0  # tnear
        f[7 * w + j] = 0.0  # time
        buf[9 * w + j] = 0xFFFFFFFF  # mask
        buf[10 * w + j] = 0  # id
        buf[11 * w + j] = 0  # flags
        valid[j] = -1


INTERSECT = 0
OCCLUDED = 1


@njit(cache=True, nogil=True, inline="always")
def _query(kind, width, scene, ptr, aptr):
    """One Embree call on the packet at ``ptr`` (its valid mask at word ``_VALID_WORD``) with
    the query arguments at ``aptr``."""
    vptr = ptr + 4 * _VALID_WORD
    if kind == INTERSECT:
        if width == 1:
            _intersect1(scene, ptr, aptr)
        elif width == 4:
            _intersect4(vptr, scene, ptr, aptr)
        elif width == 8:
            _intersect8(vptr, scene, ptr, aptr)
        else:
            _intersect16(vptr, scene, ptr, aptr)
    elif width == 1:
        _occluded1(scene, ptr, aptr)
    elif width == 4:
        _occluded4(vptr, scene, ptr, aptr)
    elif width == 8:
        _occluded8(vptr, scene, ptr, aptr)
    else:
        _occluded16(vptr, scene, ptr, aptr)


@njit(cache=True, nogil=True, inline="always")
def _load_packet(buf, w, o, d, t_in, a, closest):
    """Rays ``a .. a + n - 1`` of (o, d) with ``tfar`` from ``t_in`` into the width-``w``
    packet in ``buf`` (made ready by :func:`_prepare_packet`), lanes past ``n`` marked invalid;
    for a ``closest``-hit query the hit's primID, geomID and instID[0] reset to invalid (as
    Embree asks). Returns ``n``.

    Only these fields change from ray to ray (the lane-by-lane copy of every field cost ~11 ns
    a ray, a quarter of a camera ray's whole query).
    """
    f = buf.view(np.float32)
    n = min(w, o.shape[0] - a)
    for j in range(n):
        i = a + j
        f[j] = o[i, 0]
        f[w + j] = o[i, 1]
        f[2 * w + j] = o[i, 2]
        f[4 * w + j] = d[i, 0]
        f[5 * w + j] = d[i, 1]
        f[6 * w + j] = d[i, 2]
        f[8 * w + j] = t_in[i]
        if closest:
            buf[17 * w + j] = 0xFFFFFFFF  # primID
            buf[18 * w + j] = 0xFFFFFFFF  # geomID
            buf[19 * w + j] = 0xFFFFFFFF  # instID[0]
    if n < w:  # the call's last packet: the lanes beyond its rays are left out
        valid = buf[_VALID_WORD: _VALID_WORD + 16].view(np.int32)
        for j in range(n, w):
            valid[j] = 0
    return n


@njit(**_SERIAL)
def intersect(scene, o, d, width, buf, tfar, prim, counters, coherent=False):
    """Closest hits of rays ``o + t d`` (float32 (m, 3), render frame), ``width`` at a time.

    Writes ``tfar`` (float32 (m,); 1e37 where missed, as embreex) and ``prim`` (int32 (m,), -1
    where missed). ``width`` must be one :func:`check_width` accepted; ``buf`` is a
    :func:`packet_buffer`. ``counters[0]`` += rays, ``counters[1]`` += seconds spent.
    ``coherent``: the rays are given to Embree as coherent (a traversal hint only).
    """
    t0 = now_s()
    m = o.shape[0]
    f = buf.view(np.float32)
    ptr = buf.ctypes.data
    aptr = ptr + 4 * (_ARGS_WORD_COHERENT if coherent else _ARGS_WORD_INCOHERENT)
    tfar[:] = TFAR_CLOSEST
    _prepare_packet(buf, width)
    for a in range(0, m, width):
        n = _load_packet(buf, width, o, d, tfar, a, True)
        _query(INTERSECT, width, scene, ptr, aptr)
        for j in range(n):
            tfar[a + j] = f[8 * width + j]
            p = buf[17 * width + j]
            prim[a + j] = -1 if p == 0xFFFFFFFF else np.int32(p)
    counters[0] += m
    counters[1] += now_s() - t0


@njit(**_SERIAL)
def occluded(scene, o, d, tmax, width, buf, out, counters, coherent=False):
    """Occlusion of the segments ``o + t d``, 0 < t < ``tmax`` (float32), ``width`` at a time.

    Writes ``out`` (int32 (m,)): 0 where something blocks the segment, -1 where it is free
    (embreex's convention; Embree 4 marks a blocked ray by ``tfar = -inf``). Same ``width``,
    ``buf``, ``counters`` and ``coherent`` as :func:`intersect`.
    """
    t0 = now_s()
    m = o.shape[0]
    f = buf.view(np.float32)
    ptr = buf.ctypes.data
    aptr = ptr + 4 * (_ARGS_WORD_COHERENT if coherent else _ARGS_WORD_INCOHERENT)
    _prepare_packet(buf, width)
    for a in range(0, m, width):
        n = _load_packet(buf, width, o, d, tmax, a, False)
        _query(OCCLUDED, width, scene, ptr, aptr)
        for j in range(n):
            out[a + j] = 0 if f[8 * width + j] < 0.0 else -1
    counters[0] += m
    counters[1] += now_s() - t0
