"""A Bluesky scan of the simulated rig: ``RE(bp.scan([camera], turntable, -60, 60, 5))``.

    python examples/bluesky_scan.py --out DIR [--scene FILE] [--spp N] [--suns S]

Starts the simulated rig (the SMC100, Oriel and pico flexx simulators, our real drivers
talking their bytes; the camera renders the satellite ground test for the turntable's angle),
makes its ophyd-async devices (:func:`drivers.bluesky.simulated.simulated_devices`), lights the
solar simulator and opens its shutter, then runs the scan: five frames at -60, -30, 0, 30 and
60 deg. It writes into DIR

- ``documents.jsonl``: every document of the run, ``{"name": ..., "doc": ...}`` a line
  (Bluesky's own ``JSONLinesWriter``);
- ``frames.h5``: the camera's frames, a NeXus HDF5 stack (``/entry/depth/data`` is
  (5, 171, 224), ...), which the run's StreamResource / StreamDatum documents point into;

and prints a short summary. Needs the ``bluesky`` extra (``pip install -e '.[bluesky]'``);
docs/export-bluesky.md reads the documents back and follows them to the frames.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "examples" / "satellite_ground_test.yaml"
DOCUMENTS = "documents.jsonl"
FRAMES = "frames"  # the camera's file is FRAMES + ".h5"
#: the scan: from, to, points [deg]
SCAN = (-60.0, 60.0, 5)


def run_scan(out: Path, *, scene: Path | None = SCENE, spp: int = 4, suns: float = 1.0,
             on_frame: Callable[..., None] | None = None,
             on_document: Callable[[str, dict], None] | None = None) -> dict[str, Any]:
    """Run the scan on a fresh simulated rig, writing into ``out``; returns a summary.

    ``on_frame(index, raw, frame)`` is handed each frame the camera wrote and
    ``on_document(name, doc)`` each document (beside the JSON lines file).
    """
    import bluesky.plan_stubs as bps
    import bluesky.plans as bp
    from bluesky import RunEngine
    from bluesky.callbacks.json_writer import JSONLinesWriter
    from bluesky.simulators import check_limits
    from ophyd_async.core import StaticFilenameProvider, StaticPathProvider
    from ophyd_async.plan_stubs import ensure_connected

    from drivers.bluesky.simulated import simulated_devices

    out = out.resolve()  # ophyd-async's path providers take absolute paths only
    out.mkdir(parents=True, exist_ok=True)
    # the example's own output of an earlier run goes: the JSON writer appends to a file it
    # finds, and the camera refuses to write over an existing frames file
    (out / DOCUMENTS).unlink(missing_ok=True)
    (out / f"{FRAMES}.h5").unlink(missing_ok=True)
    counts: collections.Counter[str] = collections.Counter()
    frames: list[tuple[int, float, int]] = []

    def frame_seen(index: int, raw: Any, frame: Any) -> None:
        depth = frame.image.depth_z_m[frame.image.valid]
        frames.append((index, float(np.median(depth)) if depth.size else float("nan"),
                       int(frame.image.valid.sum())))
        if on_frame is not None:
            on_frame(index, raw, frame)

    RE = RunEngine({})
    RE.subscribe(JSONLinesWriter(str(out), DOCUMENTS))
    RE.subscribe(lambda name, doc: counts.update([name]))
    if on_document is not None:
        RE.subscribe(on_document)
    t0 = time.perf_counter()
    path_provider = StaticPathProvider(StaticFilenameProvider(FRAMES), out)
    with simulated_devices(path_provider, scene=scene, spp=spp, on_frame=frame_seen) as rig:
        RE(ensure_connected(*rig))
        RE(bps.mv(rig.solar, suns, rig.solar.shutter, True))
        start, stop, num = SCAN
        # every point within the turntable's limits before anything moves (a plan's own run
        # would stop at the first point beyond them, the table already moved)
        check_limits(bp.scan([rig.camera], rig.turntable, start, stop, num))
        (uid,) = RE(bp.scan([rig.camera], rig.turntable, start, stop, num))
    return {"uid": uid, "documents": dict(counts), "frames": frames,
            "files": [out / DOCUMENTS, out / f"{FRAMES}.h5"],
            "seconds": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the documents "
                        "(documents.jsonl) and the frames (frames.h5)")
    parser.add_argument("--scene", type=Path, default=SCENE, help="scene file the simulated "
                        "camera renders (default: the satellite ground test)")
    parser.add_argument("--spp", type=int, default=4, help="samples per pixel of the "
                        "simulated camera's path tracer (default 4: fast, noisy)")
    parser.add_argument("--suns", type=float, default=1.0, help="solar simulator level "
                        "(0, or 0.8 to 1.2 sun; default 1)")
    args = parser.parse_args(argv)
    summary = run_scan(args.out, scene=args.scene, spp=args.spp, suns=args.suns)
    docs = ", ".join(f"{n} {name}" for name, n in summary["documents"].items())
    print(f"run {summary['uid']}: {docs} ({summary['seconds']:.1f} s)")
    for index, median_m, valid in summary["frames"]:
        angle = SCAN[0] + index * (SCAN[1] - SCAN[0]) / (SCAN[2] - 1)
        print(f"  frame {index} at {angle:+5.1f} deg: {valid} valid pixels, median depth "
              f"{median_m:.3f} m")
    print("written: " + ", ".join(str(f) for f in summary["files"]))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))  # run from a clone without installing it
    sys.exit(main())
