"""Per-object reflectance scales from the measured amplitude (issue 14, section 3).

At a given mount pose the twin renders every view with the current scales
(:mod:`calibration.object_twin.render_model`); over each object's pixels (those whose pixel
centre sees it in the prediction, one pixel in from its silhouette, usable in the measurement)
the measured phasor ``z_m`` is, to first order, the predicted one ``z_p`` times the ratio of the
true scale to the current one, so the least-squares ratio is

    k = sum w Re(conj(z_p) z_m) / sum w |z_p|^2

and ``s k`` is the starting scale of the joint fit (:mod:`calibration.object_twin.refine`),
which adjusts scales and pose together and gives the uncertainties.

An object with too few pixels, or too little signal, in all views is *undetermined*: it keeps
the scale 1.0 and the reason is reported (the black flannel pedestal under the body, for one).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from calibration.object_twin.render_model import PredictedView

#: least pixels of an object over all views for its scale to be determined
MIN_PIXELS = 40
#: least mean predicted amplitude of those pixels [DN]. Below it the twin's own errors on the
#: object are as large as the scale's tolerance: on a simulated-lab round trip the black flannel
#: pedestal (192 pixels at 12 DN, under the bright body) measured 3 % darker than the twin at the
#: true pose and scale, and the fit, with the pose within 0.12 mm and 0.02 deg, moved its scale
#: 9 % off absorbing the residuals at the body's silhouette next to it: a dim object's scale is
#: reported as not determined rather than fitted badly
MIN_AMPLITUDE_DN = 20.0


@dataclass(frozen=True)
class ObjectPixels:
    """Which pixels of which view show an object, and whether that determines its scale."""

    name: str
    masks: tuple[np.ndarray, ...] = field(repr=False)
    n_pixels: int = 0
    mean_amplitude_dn: float = 0.0
    determined: bool = False
    reason: str = ""


def object_pixels(names: tuple[str, ...], scene_names: tuple[str, ...],
                  predicted: list[PredictedView], usable: list[np.ndarray],
                  min_pixels: int = MIN_PIXELS,
                  min_amplitude_dn: float = MIN_AMPLITUDE_DN) -> dict[str, ObjectPixels]:
    """Each named object's interior pixels per view and whether they determine its scale.

    ``scene_names`` are the scene's object names (``object_id`` indexes them); ``usable`` the
    measured pixels with signal that the camera did not flag, per view.
    """
    out = {}
    for name in names:
        k = scene_names.index(name)
        masks = []
        amps = []
        for pred, use in zip(predicted, usable, strict=True):
            inner = ndimage.binary_erosion(pred.object_id == k, iterations=1)
            m = inner & use & ~pred.saturated
            masks.append(m)
            amps.append(pred.amplitude[m])
        a = np.concatenate(amps) if amps else np.zeros(0)
        n = int(a.size)
        mean = float(a.mean()) if n else 0.0
        if n < min_pixels:
            ok, reason = False, (f"{n} usable pixels over all views (at least {min_pixels} "
                                 "needed): not seen enough")
        elif mean < min_amplitude_dn:
            ok, reason = False, (f"mean amplitude {mean:.1f} DN (at least {min_amplitude_dn:g} "
                                 "DN needed): too little signal")
        else:
            ok, reason = True, ""
        out[name] = ObjectPixels(name, tuple(masks), n, mean, ok, reason)
    return out


def scale_ratio(measured: list[np.ndarray], predicted: list[PredictedView],
                masks: tuple[np.ndarray, ...], weights: list[np.ndarray]) -> float:
    """The least-squares ratio ``k`` of measured to predicted phasors (first frequency) over
    ``masks``; ``measured`` as :func:`calibration.object_twin.render_model.measured_phasor`."""
    num = den = 0.0
    for zm_all, pred, m, w in zip(measured, predicted, masks, weights, strict=True):
        zm = zm_all[0]
        zp = pred.phasor[0][m]
        num += float(np.sum(w[m] * np.real(np.conj(zp) * zm[m])))
        den += float(np.sum(w[m] * np.abs(zp) ** 2))
    return num / den if den > 0.0 else 1.0
