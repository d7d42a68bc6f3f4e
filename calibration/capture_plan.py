"""What a calibration procedure needs captured, and the captures it is handed back.

Calibration never drives the rig. Each procedure declares a :class:`CapturePlan` (mounts,
waits and captures, in order); the service runs it on the rig
(:func:`service.lab.acquisition.acquire`: the operator mounts, the rig waits, moves and
captures, the frames are averaged) and hands the
:class:`~calibration.captures.AveragedCapture` of every :class:`CaptureStep` back, keyed by the
step's name (:data:`Captures`), to the procedure's fit. The plan names the rig state in its own
plain values (turntable angle, solar level, shutter), so calibration imports no driver (an
import-linter contract).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

from calibration.captures import AveragedCapture
from sim_core.errors import InvalidInputError
from sim_core.scene_spec import ObjectSpec


@dataclass(frozen=True)
class CaptureStep:
    """One rig state captured: ``frames`` frames, averaged.

    Attributes
    ----------
    name : str
        The key of its capture in :data:`Captures` (unique within a plan).
    turntable_angle_deg : float
        Reported turntable angle to move to [deg].
    solar_suns : float
        Set level of the solar simulator [sun] (0: lamp out).
    shutter_open : bool
        Whether the solar simulator's shutter lets the light through.
    frames : int
        Frames averaged (at least 1).
    keep_frames : bool
        Keep the individual frames in the capture (noise stacks, standard errors).
    message : str
        What the step does, in words (progress).
    settle : bool
        Wait for the turntable to settle after the move before the exposure (the driver's and
        the service's wait); False: capture at once after the move, while the table may still
        ring (the settling stage, :mod:`calibration.rig_settling`).
    rest_s : float
        Seconds more, after the move and its wait, before the exposure (finite, 0 to
        :data:`MAX_WAIT_S`): the table at rest where how it rings is not yet known (the
        warm-up stage's first capture, before the settling stage has measured the ringing).
    """

    name: str
    turntable_angle_deg: float
    solar_suns: float
    shutter_open: bool
    frames: int
    keep_frames: bool = False
    message: str = ""
    settle: bool = True
    rest_s: float = 0.0

    def __post_init__(self) -> None:
        if not math.isfinite(self.turntable_angle_deg):
            raise InvalidInputError(f"{self.name}.turntable_angle_deg",
                                    f"got {self.turntable_angle_deg!r}; a finite angle")
        if not (math.isfinite(self.solar_suns) and self.solar_suns >= 0.0):
            raise InvalidInputError(f"{self.name}.solar_suns",
                                    f"got {self.solar_suns!r}; 0 (lamp off) or a level in suns")
        if self.frames < 1:
            raise InvalidInputError(f"{self.name}.frames", f"got {self.frames}; at least 1")
        if not (math.isfinite(self.rest_s) and 0.0 <= self.rest_s <= MAX_WAIT_S):
            raise InvalidInputError(f"{self.name}.rest_s", f"got {self.rest_s!r}; allowed: 0 to "
                                    f"{MAX_WAIT_S:g} s")


@dataclass(frozen=True)
class MountStep:
    """The operator swaps what stands on the turntable.

    Attributes
    ----------
    objects : tuple of ObjectSpec or None
        What to mount (world frame at the turntable's zero); None: the test object again.
    instruction : str
        The same in words, for the operator.
    """

    objects: tuple[ObjectSpec, ...] | None
    instruction: str


@dataclass(frozen=True)
class WaitStep:
    """Time passes with nothing captured and nothing moved (a warm-up sequence's pause between
    captures): a real rig sleeps, the simulated lab advances its clock
    (:meth:`drivers.rig.Rig.wait`).

    Attributes
    ----------
    seconds : float
        How long [s] (finite, >= 0).
    message : str
        What the wait is for, in words (progress).
    """

    seconds: float
    message: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.seconds) and 0.0 <= self.seconds <= MAX_WAIT_S):
            raise InvalidInputError("wait.seconds", f"got {self.seconds!r}; allowed: 0 to "
                                    f"{MAX_WAIT_S:g} s")


#: the longest single wait a plan may ask for [s] (a day: a longer one is a mistake)
MAX_WAIT_S = 86_400.0
#: a plan's step
Step = CaptureStep | MountStep | WaitStep
#: what a plan's captures gave: step name -> averaged capture, in the plan's order
Captures = Mapping[str, AveragedCapture]


@dataclass(frozen=True)
class CapturePlan:
    """Mounts and captures, in order.

    Attributes
    ----------
    steps : tuple of CaptureStep, MountStep or WaitStep
    restore : MountStep or None
        A mount done after the steps even when one of them fails (the test object back).
    """

    steps: tuple[Step, ...]
    restore: MountStep | None = None

    def __post_init__(self) -> None:
        names = [s.name for s in self.captures]
        if len(set(names)) != len(names):
            twice = next(n for n in names if names.count(n) > 1)
            raise InvalidInputError("steps", f"capture '{twice}' is planned twice; each once")

    @property
    def captures(self) -> tuple[CaptureStep, ...]:
        """The capture steps, in order."""
        return tuple(s for s in self.steps if isinstance(s, CaptureStep))

    @property
    def waited_s(self) -> float:
        """The seconds the plan's waits and its captures' rests add up to."""
        return float(sum(s.seconds for s in self.steps if isinstance(s, WaitStep))
                     + sum(s.rest_s for s in self.captures))

    @property
    def n_captures(self) -> int:
        """Rig states the plan visits (for progress)."""
        return len(self.captures)

    def rested_after_moves(self, rest_s: float, from_angle_deg: float | None = None
                           ) -> CapturePlan:
        """This plan with every capture that follows a move of the turntable (its angle not the
        previous capture's, the first one's not ``from_angle_deg``) resting at least ``rest_s``
        after it; captures taken on purpose while the table moves (``settle=False``) keep none.

        >>> plan = CapturePlan(tuple(CaptureStep(f"c{i}", a, 0.0, False, 1)
        ...                          for i, a in enumerate((0.0, 0.0, 5.0))))
        >>> [c.rest_s for c in plan.rested_after_moves(120.0, 0.0).captures]
        [0.0, 0.0, 120.0]
        """
        if not (math.isfinite(rest_s) and 0.0 <= rest_s <= MAX_WAIT_S):
            raise InvalidInputError("rest_s", f"got {rest_s!r} s; 0..{MAX_WAIT_S:g} s")
        steps: list[Step] = []
        angle = from_angle_deg
        for step in self.steps:
            if isinstance(step, CaptureStep):
                if step.settle and step.turntable_angle_deg != angle:
                    step = replace(step, rest_s=max(step.rest_s, rest_s))
                angle = step.turntable_angle_deg
            steps.append(step)
        return CapturePlan(tuple(steps), self.restore)


def mount(objects: Sequence[ObjectSpec] | None, instruction: str) -> MountStep:
    """A :class:`MountStep` from any sequence of objects (or None)."""
    return MountStep(None if objects is None else tuple(objects), instruction)


class Operator(Protocol):
    """Whoever swaps what stands on the turntable: the operator, or the simulated lab."""

    def mount(self, objects: Sequence[ObjectSpec] | None, instruction: str) -> None:
        """Mount ``objects`` (world frame at the turntable's zero) or, with None, the test
        object again; ``instruction`` says it in words."""
