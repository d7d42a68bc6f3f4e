"""Lists of turntable angles: the one grammar for angles given as text, and the sweep rule.

**The grammar** (:func:`parse_angles`): every option or field that takes turntable angles as
text (``toftwin fit-object --angles``, ``toftwin calibrate material --angles``; the operator
page's campaign form mirrors it in ``service/web/static/page.js`` for instant feedback) reads
either

* a list: numbers separated by commas and/or spaces, ``"-30, -10, 10, 30"``; or
* a range: ``"FROM:TO:STEP"``, the angles FROM, FROM + STEP, ... up to TO, the end included
  when a step reaches it (``"-10:10:5"`` is ``-10, -5, 0, 5, 10``; ``"0:10:4"`` is ``0, 4, 8``).
  STEP is positive and TO is not below FROM.

Numbers are decimals (``12``, ``-12.5``, ``1e1``); every angle is finite. The range's angles are
rounded to 1e-9 deg, so that ``0:1:0.1`` gives ``0.3`` rather than ``0.30000000000000004``.
What a caller allows (the angles' span, how many, whether each only once: an
:class:`AngleLimits`) is given with each call, and an error names the option or field the
caller gives and the allowed range.

**The sweep rule** (:func:`sweep_angles`): the board sweep of the rig calibration
(``toftwin calibrate rig --sweep-from --sweep-to --sweep-step`` and the service's
``POST /calibrations`` ``sweep: {from_deg, to_deg, step_deg}``) is the range FROM:TO:STEP of the
grammar, with the limits of :data:`SWEEP_STEP_RANGE_DEG` and :data:`SWEEP_COUNT_RANGE`.

This module imports nothing heavy: the command line reads its ranges when it starts.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from sim_core.errors import InvalidInputError

#: a turntable angle as the command line and the service take it [deg] (the stage's own software
#: limits are checked where the rig moves)
ANGLE_RANGE_DEG: tuple[float, float] = (-360.0, 360.0)
#: most angles any list may hold: one every half degree over the whole range of one side
MAX_ANGLES = 721
#: a decimal number as the grammar reads it (what JavaScript's ``Number`` reads too)
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
#: what separates the numbers of a list
_SEPARATOR = re.compile(r"[,\s]+")
#: an example of each form, for the messages
_FORMS = "give FROM:TO:STEP (e.g. -30:30:10) or a list (e.g. -30, 0, 30)"


@dataclass(frozen=True)
class AngleLimits:
    """What a caller allows of a list of turntable angles (:func:`parse_angles`,
    :func:`check_angles`).

    Attributes
    ----------
    lo_deg, hi_deg : float
        Each angle is in [lo_deg, hi_deg].
    min_count, max_count : int
        How many angles are allowed.
    distinct : bool
        Whether each angle may appear only once.
    why_range : str
        Why the angles keep to [lo_deg, hi_deg], said when one does not.
    """

    lo_deg: float = ANGLE_RANGE_DEG[0]
    hi_deg: float = ANGLE_RANGE_DEG[1]
    min_count: int = 1
    max_count: int = MAX_ANGLES
    distinct: bool = False
    why_range: str = ""


#: any turntable angles: 1 to :data:`MAX_ANGLES` in :data:`ANGLE_RANGE_DEG`, repeats allowed
ANY_ANGLES = AngleLimits()


def parse_angles(text: str, *, field: str,
                 limits: AngleLimits = ANY_ANGLES) -> tuple[float, ...]:
    """The turntable angles [deg] of ``text``: ``"FROM:TO:STEP"`` or ``"a, b, c"``.

    Parameters
    ----------
    text : str
        The angles as typed.
    field : str
        The option or field the errors name (``"--angles"``).
    limits : AngleLimits
        Their span, how many, whether each only once.

    Raises
    ------
    InvalidInputError
        Naming ``field``: text of neither form, a number that is not finite or outside
        [lo_deg, hi_deg], too few or too many angles, an angle twice (with ``distinct``).

    >>> parse_angles("-10:10:5", field="--angles")
    (-10.0, -5.0, 0.0, 5.0, 10.0)
    >>> parse_angles("0, 12.5 30", field="--angles")
    (0.0, 12.5, 30.0)
    >>> parse_angles("0, 0", field="--angles", limits=AngleLimits(distinct=True))
    Traceback (most recent call last):
    ...
    sim_core.errors.InvalidInputError: --angles: 0 deg is given twice; allowed: each angle once
    """
    t = str(text).strip()
    if ":" in t:
        parts = [p.strip() for p in t.split(":")]
        if len(parts) != 3:
            raise InvalidInputError(field, f"'{t}' has {len(parts)} parts; {_FORMS}")
        start, stop, step = (_number(p, field) for p in parts)
        angles = angle_range(start, stop, step, field=field, max_count=limits.max_count)
    else:
        angles = tuple(_number(p, field) for p in _SEPARATOR.split(t) if p)
    return check_angles(angles, field=field, limits=limits)


def angle_range(
    start_deg: float, stop_deg: float, step_deg: float, *, field: str,
    max_count: int = MAX_ANGLES,
) -> tuple[float, ...]:
    """``start_deg``, ``start_deg + step_deg``, ... up to ``stop_deg`` [deg], the end included
    when a step reaches it (within 1e-9 of a step); each rounded to 1e-9 deg, none past
    ``stop_deg``.

    The range form of :func:`parse_angles` and the board sweep (:func:`sweep_angles`).

    >>> angle_range(-55, 55, 45, field="sweep")
    (-55.0, -10.0, 35.0)
    """
    for name, v in (("FROM", start_deg), ("TO", stop_deg), ("STEP", step_deg)):
        if not math.isfinite(v):
            raise InvalidInputError(field, f"{name} is {v!r}; allowed: a finite number")
    if not step_deg > 0.0:
        raise InvalidInputError(field, f"STEP is {step_deg:g} deg; allowed: above 0")
    if stop_deg < start_deg:
        raise InvalidInputError(field, f"TO ({stop_deg:g}) is below FROM ({start_deg:g}) deg; "
                                "allowed: TO >= FROM")
    steps = (stop_deg - start_deg) / step_deg + 1e-9  # inf when the span overflows
    if not steps < max_count:  # before the list is made: a tiny step must not fill the memory
        many = f"{math.floor(steps) + 1}" if math.isfinite(steps) else "too many"
        raise InvalidInputError(field, f"{start_deg:g} to {stop_deg:g} every {step_deg:g} deg is "
                                f"{many} angles; allowed: at most {max_count} (a coarser step)")
    n = math.floor(steps) + 1
    # rounded to 1e-9 deg, never past the end (the last step may reach it within 1e-9 step)
    return tuple(min(round(start_deg + i * step_deg, 9), stop_deg) + 0.0 for i in range(n))


def check_angles(angles: Sequence[float], *, field: str,
                 limits: AngleLimits = ANY_ANGLES) -> tuple[float, ...]:
    """``angles`` as floats if they keep the ``limits``, else an input error naming ``field``
    and the allowed range."""
    lo, hi, why = limits.lo_deg, limits.hi_deg, limits.why_range
    out = tuple(float(a) for a in angles)
    if not limits.min_count <= len(out) <= limits.max_count:
        raise InvalidInputError(field, f"{len(out)} angle(s); allowed: {limits.min_count} to "
                                f"{limits.max_count}")
    bad = [a for a in out if not (math.isfinite(a) and lo <= a <= hi)]
    if bad:
        raise InvalidInputError(field, f"{bad[0]!r} deg is outside the allowed [{lo:g}, "
                                f"{hi:g}] deg" + (f" ({why})" if why else ""))
    if limits.distinct and len(set(out)) != len(out):
        twice = next(a for i, a in enumerate(out) if a in out[:i])
        raise InvalidInputError(field, f"{twice:g} deg is given twice; allowed: each angle once")
    return out


def _number(text: str, field: str) -> float:
    if not _NUMBER.fullmatch(text):
        raise InvalidInputError(field, f"'{text}' is not a number; {_FORMS}")
    return float(text)


# -- the board sweep of the rig calibration -----------------------------------------------------
#: the default sweep [deg]: -55 ... 55 every 5 deg (docs/calibration.md)
SWEEP_FROM_DEG, SWEEP_TO_DEG, SWEEP_STEP_DEG = -55.0, 55.0, 5.0
#: the sweep's step [deg]
SWEEP_STEP_RANGE_DEG: tuple[float, float] = (0.5, 90.0)
#: angles of a sweep: three or more determine the turntable's axis
SWEEP_COUNT_RANGE: tuple[int, int] = (3, MAX_ANGLES)
#: the names of the sweep's inputs as the service's request gives them (the command line passes
#: its options' names)
SWEEP_FIELDS: Mapping[str, str] = {"sweep": "sweep", "from_deg": "sweep.from_deg",
                                   "to_deg": "sweep.to_deg", "step_deg": "sweep.step_deg"}


def sweep_angles(
    from_deg: float = SWEEP_FROM_DEG,
    to_deg: float = SWEEP_TO_DEG,
    step_deg: float = SWEEP_STEP_DEG,
    *,
    fields: Mapping[str, str] = SWEEP_FIELDS,
) -> tuple[float, ...]:
    """The board sweep's reported angles [deg]: the range ``from_deg:to_deg:step_deg`` of
    :func:`parse_angles`.

    The one rule of the command line (``toftwin calibrate rig``) and the service
    (``POST /calibrations``). Before it, the command line swept -55 ... 55 deg only, every 1 to
    30 deg, and the service took any span in [-360, 360] deg every 0.5 to 90 deg with 3 to 721
    angles; the service's rule is kept (every plan either side could make is still made, the
    same; the command line gains the span), so a command-line step of 30-90 deg that gives 3
    angles or more is now allowed.

    ``fields`` names the inputs in the errors (keys ``sweep``, ``from_deg``, ``to_deg``,
    ``step_deg``). The stage's own software limits are checked where the rig is known.

    >>> sweep_angles(-30, 30, 20)
    (-30.0, -10.0, 10.0, 30.0)
    """
    lo, hi = ANGLE_RANGE_DEG
    for key, v in (("from_deg", from_deg), ("to_deg", to_deg)):
        if not (math.isfinite(v) and lo <= v <= hi):
            raise InvalidInputError(fields[key], f"got {v!r} deg; allowed: {lo:g} to {hi:g} deg")
    s_lo, s_hi = SWEEP_STEP_RANGE_DEG
    if not (math.isfinite(step_deg) and s_lo <= step_deg <= s_hi):
        raise InvalidInputError(fields["step_deg"], f"got {step_deg!r} deg; allowed: {s_lo:g} "
                                f"to {s_hi:g} deg")
    if not to_deg > from_deg:
        raise InvalidInputError(fields["sweep"], f"{fields['to_deg']} ({to_deg:g}) must be "
                                f"greater than {fields['from_deg']} ({from_deg:g})")
    n_lo, n_hi = SWEEP_COUNT_RANGE
    try:
        angles = angle_range(from_deg, to_deg, step_deg, field=fields["step_deg"],
                             max_count=n_hi)
    except InvalidInputError as exc:  # too many: a coarser step
        raise InvalidInputError(fields["step_deg"], exc.message) from None
    if len(angles) < n_lo:
        raise InvalidInputError(
            fields["sweep"], f"{len(angles)} angle(s) from {from_deg:g} to {to_deg:g} deg every "
            f"{step_deg:g} deg; allowed: {n_lo} to {n_hi} (at least {n_lo} are needed to "
            "determine the turntable's axis)")
    return angles
