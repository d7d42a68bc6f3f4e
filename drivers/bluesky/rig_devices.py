"""The three devices of one rig, over the rig's drivers and behind the rig's lock.

:func:`rig_devices` makes the turntable (:class:`~drivers.bluesky.movables.TurntableMotor`),
the solar simulator's level (:class:`~drivers.bluesky.movables.SolarLevel`) and the camera
(:class:`~drivers.bluesky.camera.ToFCamera`) of a :class:`drivers.rig.Rig`, the real one
(:meth:`drivers.rig.Rig.open`) or the simulated one (:mod:`drivers.bluesky.simulated`). Every
driver call holds the rig (:meth:`~drivers.rig.Rig.hold`), so a RunEngine driving them never
interleaves with another user of the same rig, and each frame is written with the rig state
read just before its capture.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from ophyd_async.core import PathProvider

from drivers.bluesky.camera import CameraModel, OnFrame, ToFCamera
from drivers.bluesky.movables import SolarLevel, TurntableMotor
from drivers.rig import Rig

__all__ = ["RigDevices", "rig_devices"]


@dataclass
class RigDevices:
    """A rig's ophyd-async devices (not yet connected: ``RE(ensure_connected(*devices))``)
    and the rig they drive; closing closes the rig. Iterating gives the three devices."""

    turntable: TurntableMotor
    solar: SolarLevel
    camera: ToFCamera
    rig: Rig

    def __iter__(self) -> Iterator[TurntableMotor | SolarLevel | ToFCamera]:
        return iter((self.turntable, self.solar, self.camera))

    def close(self) -> None:
        """Close the rig (its drivers, and a simulated rig's simulators)."""
        self.rig.close()

    def __enter__(self) -> RigDevices:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def rig_devices(rig: Rig, path_provider: PathProvider, *,
                camera_model: CameraModel | None = None, on_frame: OnFrame | None = None,
                wait_stable_s: float | None = None,
                names: tuple[str, str, str] = ("turntable", "solar", "camera")) -> RigDevices:
    """The turntable, solar level and camera devices of ``rig``, named ``names``.

    ``path_provider`` says where the camera writes each run's frames; ``camera_model`` the
    intrinsics they are reconstructed with (None: the pico flexx preset); ``on_frame`` is
    handed every frame written; ``wait_stable_s`` makes a level wait for the lamp's output to
    be stable (:class:`~drivers.bluesky.movables.SolarLevel`).
    """
    tt_name, solar_name, camera_name = names
    return RigDevices(
        turntable=TurntableMotor(rig.turntable, hold=rig.hold, name=tt_name),
        solar=SolarLevel(rig.solar, hold=rig.hold, wait_stable_s=wait_stable_s,
                         name=solar_name),
        camera=ToFCamera(rig.camera, path_provider, camera_model=camera_model, hold=rig.hold,
                         rig_state=rig.state, on_frame=on_frame, name=camera_name),
        rig=rig,
    )
