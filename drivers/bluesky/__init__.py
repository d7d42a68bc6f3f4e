"""Bluesky on the rig: ophyd-async devices over our drivers (the ``bluesky`` extra).

- :mod:`drivers.bluesky.movables`: :class:`TurntableMotor` (degrees, with the controller's
  limits) and :class:`SolarLevel` (suns; the shutter and the lamp switch as signals).
- :mod:`drivers.bluesky.camera`: :class:`ToFCamera`, an ophyd-async ``StandardDetector`` whose
  frames go to one NeXus HDF5 file per run, announced in StreamResource / StreamDatum
  documents.
- :mod:`drivers.bluesky.rig_devices`: :func:`rig_devices`, the three devices of one
  :class:`drivers.rig.Rig` behind its lock.
- :mod:`drivers.bluesky.simulated`: :func:`~drivers.bluesky.simulated.simulated_devices`, the
  same devices on the device simulators (imported from there: this package's other modules
  import no simulator).

``pip install -e '.[bluesky]'`` installs bluesky and ophyd-async; docs/export-bluesky.md has a
scan to run. The names below are loaded on first use, so that importing the package (pytest
does, for its conftest) needs neither.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "SolarLevel": "drivers.bluesky.movables",
    "TurntableMotor": "drivers.bluesky.movables",
    "ToFCamera": "drivers.bluesky.camera",
    "RigDevices": "drivers.bluesky.rig_devices",
    "rig_devices": "drivers.bluesky.rig_devices",
}


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'drivers.bluesky' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = list(_EXPORTS)
