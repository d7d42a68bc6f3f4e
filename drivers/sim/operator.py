"""The simulated lab's operator: mounts what a procedure asks for on the simulated world.

Beside :class:`drivers.sim.world.SimulatedWorld` because it holds the simulated lab's truth:
the true material of a sample the procedure is to measure (calibration's estimators never see
it; they see only the frames).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from drivers.sim.world import SimulatedWorld
from sim_core.scene_spec import ObjectSpec

__all__ = ["SimulatedOperator"]


class SimulatedOperator:
    """The simulated lab's swap: :meth:`drivers.sim.world.SimulatedWorld.mount`.

    ``materials`` (object name -> material spec or preset name) are the true materials of what
    this operator has in hand: an object of that name is mounted with it, whatever material the
    procedure's object names (a material sample's prior). That is how the simulated lab holds a
    sample of a material the procedure is to measure without ever telling the procedure.
    """

    def __init__(self, world: SimulatedWorld, materials: Mapping[str, Any] | None = None) -> None:
        self.world = world
        self.materials = dict(materials or {})

    def mount(self, objects: Sequence[ObjectSpec] | None, instruction: str) -> None:
        if objects is not None:
            objects = [o.model_copy(update={"material": ObjectSpec.model_validate(
                {**o.model_dump(), "material": self.materials[o.name]}).material})
                if o.name in self.materials else o for o in objects]
        self.world.mount(objects)
