"""Device drivers of the rig, each a small Protocol, a pyserial implementation and a simulator.

- Turntable: a rotation stage on a Newport SMC100CC controller, RS-232
  (:class:`TurntableProtocol`, :class:`Turntable`).
- Solar simulator: an Oriel arc-lamp supply (69907 family) and a 68945 exposure controller
  (shutter), two RS-232 ports (:class:`SolarSimulatorProtocol`, :class:`SolarSimulator`).
- The ToF camera: a PMD pico flexx over USB, through royale where installed
  (:class:`drivers.camera.RoyaleCamera`) or our own bulk-transfer wire format
  (:class:`drivers.camera.UsbCamera`), behind one :class:`drivers.camera.CameraProtocol`;
  :mod:`drivers.camera` holds discovery, the wire format and both backends.
- :mod:`drivers.diagnostics` lists the cameras present and checks every device of the rig.
- :class:`drivers.rig.Rig` composes the three behind one lock.

The byte-level simulators live in :mod:`drivers.sim` (serial devices on a pseudo-terminal or a
TCP socket, the camera as a pyusb backend); ``python -m drivers.sim.pty_server KIND`` serves a
serial one on a pseudo-terminal. Protocol details and sources: ``docs/devices.md``.
"""

from drivers import errors
from drivers.errors import *  # noqa: F403 (the names of errors.__all__)
from drivers.solar_simulator import (
    SUNS_RANGE,
    SolarSimulator,
    SolarSimulatorProtocol,
    SolarStatus,
    SunsCalibration,
)
from drivers.transport import SerialSettings, SerialTransport
from drivers.turntable import ControllerStatus, Turntable, TurntableProtocol

__all__ = [
    *errors.__all__,
    "SUNS_RANGE",
    "ControllerStatus",
    "SerialSettings",
    "SerialTransport",
    "SolarSimulator",
    "SolarSimulatorProtocol",
    "SolarStatus",
    "SunsCalibration",
    "Turntable",
    "TurntableProtocol",
]
