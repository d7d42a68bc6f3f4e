"""What the object fit may claim: a verdict for each key of the object file.

The object file (:class:`sim_core.twin_file.ObjectTwinFile`) carries the mount's pose offset
(``mount.pose_offset.position_m`` [m], ``mount.pose_offset.rotation_deg`` [deg]) and each
fitted object's ``objects.<name>.reflectance_scale``. Each gets its verdict
(:mod:`calibration.verdicts`) from the fit's own evidence:

- the goodness of fit: the reduced chi-square of the whitened phasor residuals, overall and per
  view (:class:`calibration.object_twin.refine.RefinedFit`); above
  :data:`calibration.verdicts.CHI2_UNEXPLAINED`, overall or in any one view, the model does not
  explain the data and every key is ``unexplained``, naming the views that do not fit;
- the error: the Jacobian's standard deviation scaled by the residual (never below it), with
  the spread over the views (the delete-one-view jackknife) as a floor: views that disagree
  beyond their noise widen the error instead of averaging into a confident wrong number;
- identifiability: a standard deviation above the key's limit (:data:`LIMITS`, those of
  :data:`calibration.object_twin.refine.UNDETERMINED_STD`), or an object with too few pixels or
  too little signal (:mod:`calibration.object_twin.reflectance`), is ``not determined``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from calibration.object_twin.refine import UNDETERMINED_STD, RefinedFit
from calibration.object_twin.reflectance import ObjectPixels
from calibration.verdicts import CHI2_UNEXPLAINED, Verdict, Verdicts, above_limit, judge

POSITION_KEY = "mount.pose_offset.position_m"
ROTATION_KEY = "mount.pose_offset.rotation_deg"
#: each key's limit: a standard deviation above it is not determined
LIMITS = {POSITION_KEY: UNDETERMINED_STD["position_mm"] * 1e-3,
          ROTATION_KEY: UNDETERMINED_STD["rotation_deg"],
          "reflectance_scale": UNDETERMINED_STD["scale"]}


def scale_key(name: str) -> str:
    """The object file's key of an object's reflectance scale."""
    return f"objects.{name}.reflectance_scale"


def unfit_views(chi2_per_view: Sequence[float]) -> list[int]:
    """The indices of the views whose reduced chi-square is above
    :data:`calibration.verdicts.CHI2_UNEXPLAINED` (or not finite), worst first."""
    return above_limit(dict(enumerate(chi2_per_view)))


def _where(refined: RefinedFit, angles_deg: Sequence[float]) -> str:
    """The views a reason names: those that do not fit, with their chi-square."""
    bad = unfit_views(refined.chi2_per_view)
    if not bad:
        return f"all {len(angles_deg)} views together"
    return "views " + ", ".join(f"{angles_deg[i]:+g} deg (chi-square "
                                f"{refined.chi2_per_view[i]:.3g})" for i in bad)


#: why a key whose spread over the views is unbounded is not determined
ONE_VIEW = ("one view alone determines it (leaving that view out leaves it undetermined): the "
            "views cannot cross-check it; add angles that see it")


def _judged(std: float | Sequence[float], spread: float | Sequence[float], limit: float, *,
            chi2: float, unit: str, where: str) -> Verdict:
    """:func:`calibration.verdicts.judge`, with the reason of a key only one view determines."""
    verdict = judge(std, limit, reduced_chi2=chi2, spread=spread, unit=unit, where=where)
    spreads = [spread] if isinstance(spread, int | float) else list(spread)
    if verdict.verdict == "not determined" and not all(math.isfinite(s) for s in spreads):
        return Verdict("not determined", None, ONE_VIEW)
    return verdict


def object_verdicts(refined: RefinedFit, pixels: Mapping[str, ObjectPixels],
                    angles_deg: Sequence[float]) -> Verdicts:
    """The verdict of each key the object file carries (module docstring); ``pixels`` are the
    mounted objects' pixel reports, ``angles_deg`` the views' turntable angles in the fit's
    order."""
    where = _where(refined, angles_deg)
    # a view the model does not explain leaves the keys unexplained, however well the others
    # pull the chi-square of all views together below the limit
    chi2 = refined.chi2_after
    bad = unfit_views(refined.chi2_per_view)
    if bad and chi2 <= CHI2_UNEXPLAINED:
        chi2 = refined.chi2_per_view[bad[0]]  # the worst view's
    out = Verdicts()
    out.add(POSITION_KEY, _judged(refined.std_position_m, refined.jackknife_position_m,
                                  LIMITS[POSITION_KEY], chi2=chi2, unit=" m", where=where))
    out.add(ROTATION_KEY, _judged(refined.std_rotation_deg, refined.jackknife_rotation_deg,
                                  LIMITS[ROTATION_KEY], chi2=chi2, unit=" deg", where=where))
    for name, px in pixels.items():
        if not px.determined:
            out.add(scale_key(name), Verdict("not determined", None,
                                             px.reason or "too few pixels of it in the views"))
            continue
        out.add(scale_key(name), _judged(refined.std_scale[name],
                                         refined.jackknife_scale.get(name, 0.0),
                                         LIMITS["reflectance_scale"], chi2=chi2, unit="",
                                         where=where))
    return out


def estimates(offset_position_m: Sequence[float], offset_rotation_deg: Sequence[float],
              scales: Mapping[str, float]) -> dict[str, np.ndarray]:
    """A fit's value of each key (the object file's names)."""
    out = {POSITION_KEY: np.asarray(offset_position_m, dtype=np.float64),
           ROTATION_KEY: np.asarray(offset_rotation_deg, dtype=np.float64)}
    out.update({scale_key(n): np.array([float(v)]) for n, v in scales.items()})
    return out


def after_dropped_views(verdicts: Verdicts, with_dropped: Mapping[str, np.ndarray],
                        without: Mapping[str, np.ndarray], dropped_where: str) -> Verdicts:
    """The verdicts of a fit made again without the views the model does not explain
    (``dropped_where``): every key it would call determined is ``unexplained``, its reason
    saying how far leaving the views out moved it.

    The other views fitting does not clear them: an effect the twin lacks acts on every view
    and shows most in some (3 % stray light: the face-on view alone fails, while the body's
    scale is 3 % low in all of them, the refit claiming 0.1 %); a view with a cause of its
    own (someone in the view, a reflection) is better captured again than left out."""
    out = Verdicts()
    for key, v in verdicts.items():
        if v.determined:
            std = np.atleast_1d(np.asarray(v.std, dtype=np.float64))
            moved = np.abs(np.asarray(with_dropped.get(key, np.nan)) -
                           np.asarray(without.get(key, np.nan)))
            ratio = float(np.max(moved / np.maximum(std, 1e-300)))
            moved_txt = ", ".join(f"{m:.3g}" for m in np.atleast_1d(moved))
            v = Verdict("unexplained", v.std,
                        f"the model does not explain {dropped_where} (left out; leaving them "
                        f"out moved it by {moved_txt}, {ratio:.3g} standard deviations): what "
                        "it misses there may bias the other views too; capture them again if "
                        "they had a cause of their own")
        out.add(key, v)
    return out


__all__ = ["LIMITS", "ONE_VIEW", "POSITION_KEY", "ROTATION_KEY", "after_dropped_views",
           "estimates", "object_verdicts", "scale_key", "unfit_views"]
