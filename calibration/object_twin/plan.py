"""What the object fit captures: one averaged capture per turntable angle, the solar simulator's
shutter closed (the fit reads the camera's own light).

``toftwin fit-object`` and a campaign's object fit stage both ask for this plan
(:func:`object_fit_capture_plan`) and the service's acquisition takes it
(:func:`service.lab.acquisition.acquire`); the fit (:func:`calibration.object_twin.fit.fit_object`)
gets the captures in the plan's order (:func:`captures_in_order`).
"""

from __future__ import annotations

from collections.abc import Sequence

from calibration.angles import AngleLimits, check_angles
from calibration.capture_plan import CapturePlan, Captures, CaptureStep
from calibration.captures import AveragedCapture

#: how many angles the fit takes (each once)
MAX_FIT_ANGLES = 36
#: the fit's angles: 1 to :data:`MAX_FIT_ANGLES` distinct turntable angles
FIT_ANGLES = AngleLimits(max_count=MAX_FIT_ANGLES, distinct=True)


def object_fit_capture_plan(angles_deg: Sequence[float], frames: int, *,
                            field: str = "angles") -> CapturePlan:
    """``frames`` frames averaged at each of ``angles_deg`` (reported angles [deg], in order),
    the shutter closed; ``field`` is what an error names (``--angles``)."""
    angles = check_angles(angles_deg, field=field, limits=FIT_ANGLES)
    return CapturePlan(tuple(
        CaptureStep(f"object@{a:+g}", a, 0.0, shutter_open=False, frames=frames,
                    message=f"object fit: {frames} frames at {a:g} deg")
        for a in angles))


def captures_in_order(plan: CapturePlan, captures: Captures) -> list[AveragedCapture]:
    """The captures of ``plan``'s steps, in its order (what the fit takes)."""
    return [captures[step.name] for step in plan.captures]


__all__ = ["FIT_ANGLES", "MAX_FIT_ANGLES", "captures_in_order", "object_fit_capture_plan"]
