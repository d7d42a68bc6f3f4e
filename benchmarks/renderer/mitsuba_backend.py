"""Loading Mitsuba 3 for ``toftwin bench mitsuba``: find a libLLVM that Dr.Jit's LLVM backend
runs with, prove it in a child process (an LLVM too old for Dr.Jit's kernels aborts the process
that compiles them), then import Mitsuba and select the variant.

Mitsuba is a benchmark dependency only (extra ``bench``); nothing else in the product imports it,
and this module imports it lazily, so the CLI works without it.
"""

from __future__ import annotations

import glob
import os
import re

MITSUBA_VARIANT = "llvm_ad_mono"

#: where Debian and the LLVM apt repository put the shared library; version 19 first
LIBLLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so*",
    "/usr/lib/llvm-19/lib/libLLVM*.so*",
    "/usr/lib/*-linux-gnu/libLLVM-*.so*",
    "/usr/lib/*-linux-gnu/libLLVM.so.*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
)
#: Dr.Jit 1.x refuses LLVM before 15 (opaque pointers); with LLVM 15 and 16 its kernels stop in
#: LLVM's x86 instruction selection ("Cannot select: fminimum", an abort that takes the process
#: down). LLVM 19 runs them; Debian 12 ships it as libllvm19 (17 and 18 are not in Debian 12).
DRJIT_MIN_LLVM = 15
RECOMMENDED_LLVM = 19

INSTALL_HINT = (
    "Install the benchmark's dependencies from the clone: `pip install -c "
    'requirements/lock.txt -e ".[bench]"` (Mitsuba 3 and Dr.Jit, pinned), and LLVM 19\'s '
    "library: `apt-get update && apt-get install -y libllvm19` (Debian 12); if Dr.Jit still "
    "does not find it, set DRJIT_LIBLLVM_PATH to it, e.g. "
    "DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so"
)

#: the probe run in a child process before anything else: select the variant, evaluate a
#: small Dr.Jit kernel (with the min() the path integrator's Russian roulette compiles to)
#: and path-trace a sphere on an 8 x 8 film; an LLVM abort then ends the child, not the CLI
BACKEND_PROBE = """
import sys
import drjit as dr
import mitsuba as mi
mi.set_variant(sys.argv[1])
from drjit.llvm import Float
x = dr.arange(Float, 1024)
total = dr.sum(dr.minimum(x * 0.001, 0.95)) + dr.sum(x)
scene = mi.load_dict({
    "type": "scene",
    "integrator": {"type": "path", "max_depth": 4, "rr_depth": 1},
    "sensor": {"type": "perspective", "sampler": {"type": "independent", "sample_count": 2},
               "film": {"type": "hdrfilm", "width": 8, "height": 8,
                        "pixel_format": "luminance", "rfilter": {"type": "box"}}},
    "ball": {"type": "sphere", "center": [0, 0, 5], "radius": 1.0, "bsdf": {"type": "diffuse"}},
    "light": {"type": "point", "position": [0, 0, 0], "intensity": 1.0},
})
image = mi.render(scene)
dr.eval(image)
print("backend ok", total, dr.mean(image.array))
"""
PROBE_TIMEOUT_S = 300.0


def llvm_version(path: str) -> int | None:
    """The LLVM major version of a libLLVM file, from its name or the name it links to
    (``libLLVM-15.so.1``, ``libLLVM.so.19.1``, ``/usr/lib/llvm-16/lib/libLLVM.so``); None if
    the names do not say.

    >>> llvm_version("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1")
    15
    >>> llvm_version("/usr/lib/llvm-16/lib/libLLVM.so"), llvm_version("/tmp/libfoo.so")
    (16, None)
    """
    for name in (path, os.path.realpath(path)):
        base = os.path.basename(name)
        m = (re.match(r"libLLVM-(\d+)", base) or re.match(r"libLLVM\.so\.(\d+)", base)
             or re.search(r"llvm-(\d+)", name))
        if m:
            return int(m.group(1))
    return None


def _ldconfig_libllvm() -> list[str]:
    """libLLVM files the dynamic linker's cache knows (``ldconfig -p``), if it can be asked."""
    import shutil
    import subprocess

    exe = shutil.which("ldconfig") or next(
        (p for p in ("/sbin/ldconfig", "/usr/sbin/ldconfig") if os.path.isfile(p)), None)
    if exe is None:
        return []
    try:
        out = subprocess.run([exe, "-p"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return [line.rsplit("=>", 1)[1].strip() for line in out.splitlines()
            if "libLLVM" in line and "=>" in line]


def libllvm_candidates() -> list[str]:
    """Every libLLVM shared library found (the globs of :data:`LIBLLVM_GLOBS`, then the linker
    cache), one path per real file, the newest LLVM first."""
    paths = [p for pattern in LIBLLVM_GLOBS for p in sorted(glob.glob(pattern))]
    seen: dict[str, str] = {}
    for p in [*paths, *_ldconfig_libllvm()]:
        if os.path.isfile(p):
            seen.setdefault(os.path.realpath(p), p)
    return sorted(seen.values(), key=lambda p: (-(llvm_version(p) or 0), len(p)))


def find_libllvm() -> str | None:
    """Path of a libLLVM shared library, the newest found (LLVM 19 where installed); or None."""
    found = libllvm_candidates()
    return found[0] if found else None


def _describe(path: str | None) -> str:
    if not path:
        return "none"
    version = llvm_version(path)
    return f"{path} (LLVM {version if version is not None else 'of unknown version'})"


def probe_backend(variant: str, libllvm: str | None, timeout_s: float = PROBE_TIMEOUT_S,
                  code: str = BACKEND_PROBE) -> tuple[bool, str]:
    """Run the probe ``code`` (:data:`BACKEND_PROBE`) in a child process with
    ``DRJIT_LIBLLVM_PATH=libllvm`` and ``variant`` as its argument.

    Returns ``(True, "")`` if it printed "backend ok", else ``(False, what happened)``: the
    signal or exit code and the first line of LLVM's or Dr.Jit's complaint.
    """
    import subprocess
    import sys

    env = dict(os.environ)
    if libllvm:
        env["DRJIT_LIBLLVM_PATH"] = libllvm
    try:
        proc = subprocess.run([sys.executable, "-c", code, variant], env=env,
                              capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return False, f"the probe did not finish in {timeout_s:g} s"
    if proc.returncode == 0 and "backend ok" in proc.stdout:
        return True, ""
    return False, probe_failure(proc.returncode, proc.stderr)


def probe_failure(returncode: int, stderr: str) -> str:
    """What a failed probe says, in one line: how it ended and the first line of the complaint.

    >>> probe_failure(-6, "LLVM ERROR: Cannot select: 0x55d: f32 = fminimum 0x1, 0x2\\n  0x1: ...")
    'the probe was killed by SIGABRT: LLVM ERROR: Cannot select: 0x55d: f32 = fminimum 0x1, 0x2'
    """
    import signal

    if returncode < 0:
        try:
            how = f"the probe was killed by {signal.Signals(-returncode).name}"
        except ValueError:
            how = f"the probe was killed by signal {-returncode}"
    else:
        how = f"the probe exited with code {returncode}"
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    key = next((ln for ln in lines if ln.startswith("LLVM ERROR")), None)
    if key is None:  # Dr.Jit's own complaint, else the exception that ended the probe
        key = next((ln for ln in lines if "too old" in ln or "could not be found" in ln),
                   lines[-1] if lines else "")
    key = key[:300].rstrip(". ")
    return f"{how}: {key}" if key else how


def backend_failure_message(libllvm: str | None, how_found: str, detail: str) -> str:
    """The error of a backend that does not run: which libLLVM was tried, what happened, which
    LLVM Dr.Jit needs and how to install it.

    >>> m = backend_failure_message("/usr/lib/x86_64-linux-gnu/libLLVM-15.so", "found", "x")
    >>> "LLVM 15" in m and "libllvm19" in m and "DRJIT_LIBLLVM_PATH" in m
    True
    """
    version = llvm_version(libllvm) if libllvm else None
    if libllvm is None:
        why = "no libLLVM shared library was found on this machine"
    elif version is not None and version < DRJIT_MIN_LLVM:
        why = f"Dr.Jit needs LLVM {DRJIT_MIN_LLVM} or newer"
    elif version is not None and version < RECOMMENDED_LLVM:
        why = (f"Dr.Jit's kernels stop in LLVM {version}'s instruction selection (LLVM 15 and "
               f"16 cannot select 'fminimum' on x86); LLVM {RECOMMENDED_LLVM} runs them")
    elif version is None:
        why = (f"it is not a libLLVM Dr.Jit can load; LLVM {RECOMMENDED_LLVM} is known to "
               "work")
    else:
        why = f"LLVM {RECOMMENDED_LLVM} is known to work"
    others = [p for p in libllvm_candidates()
              if libllvm is None or os.path.realpath(p) != os.path.realpath(libllvm)]
    also = f" Other libLLVM found: {', '.join(_describe(p) for p in others)}." if others else ""
    return (f"Mitsuba 3 is installed but Dr.Jit's LLVM backend does not run with the libLLVM "
            f"{how_found}: {_describe(libllvm)}; {detail}. {why}.{also} {INSTALL_HINT}")


def load_mitsuba(variant: str = MITSUBA_VARIANT):
    """Import Mitsuba 3 and Dr.Jit and select ``variant``, once a child process has shown that
    Dr.Jit's LLVM backend runs (:func:`probe_backend`): with an LLVM too old for Dr.Jit's
    kernels, LLVM aborts the process that compiles them.

    Sets ``DRJIT_LIBLLVM_PATH`` (if unset) to the library :func:`find_libllvm` finds.

    Returns
    -------
    (mitsuba module, drjit module, libLLVM path or None)

    Raises
    ------
    RuntimeError
        If Mitsuba is not installed or its LLVM backend does not run, saying which libLLVM was
        tried and what to install.
    """
    llvm = os.environ.get("DRJIT_LIBLLVM_PATH")
    how_found = "DRJIT_LIBLLVM_PATH names"
    if not llvm:
        llvm = find_libllvm()
        how_found = "found"
        if llvm:
            os.environ["DRJIT_LIBLLVM_PATH"] = llvm
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:
        raise RuntimeError(
            f"The Mitsuba comparison needs Mitsuba 3, which is not installed ({exc}). "
            f"{INSTALL_HINT}"
        ) from exc
    ok, detail = probe_backend(variant, llvm)
    if not ok:
        raise RuntimeError(backend_failure_message(llvm, how_found, detail))
    try:
        mi.set_variant(variant)
        ok = bool(dr.has_backend(dr.JitBackend.LLVM))
    except Exception as exc:  # ImportError from Dr.Jit's LLVM init, AttributeError, ...
        raise RuntimeError(
            f"Mitsuba is installed but its variant {variant!r} could not be loaded "
            f"(DRJIT_LIBLLVM_PATH={os.environ.get('DRJIT_LIBLLVM_PATH')!r}): {exc}. "
            f"{INSTALL_HINT}"
        ) from exc
    if not ok:
        raise RuntimeError(
            "Mitsuba is installed but Dr.Jit's LLVM backend is inactive (libLLVM not loaded, "
            f"DRJIT_LIBLLVM_PATH={os.environ.get('DRJIT_LIBLLVM_PATH')!r}). {INSTALL_HINT}"
        )
    return mi, dr, os.environ.get("DRJIT_LIBLLVM_PATH")
