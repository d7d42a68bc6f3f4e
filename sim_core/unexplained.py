"""Where a twin's unexplained residual lives and what shape it has (issue 27).

A fitted twin that stays above the noise ceiling leaves a residual the twin does not explain.
This module sets the residual image (measured - fitted twin) against the noise image (measured -
a second capture of the same state, the ceiling) and takes the residual's excess mean square
(``mean(r^2) - mean(n^2)``) apart into the shapes a real rig's unmodelled effects leave:

``offset``
    a common offset over every compared pixel (range: a warm-up drift or a phase offset; grey:
    a gain, power or reflectance scale);
``object``
    an offset of its own on one named region (an object) beyond the common one;
``on_object``
    excess concentrated on one named region (an object), whatever its sign;
``edges``
    excess concentrated on silhouette edges (motion: a table still ringing, a capture while
    turning, or a pose error);
``dark``
    excess concentrated on dark pixels next to bright ones (stray light pulls a dark pixel's
    range towards its bright neighbours' and adds their light to its grey);
``region``
    excess concentrated in a part of the image (a third of it across and down).

Every threshold comes from the noise image: an offset counts when it is ``z`` standard errors of
the noise's mean away from zero, a concentration when its excess sum is ``z`` of the noise's
own spread of that sum above zero and the set holds at least :data:`CONCENTRATION` times its
share of the pixels. The common offset is taken out first; each region's offset and each set's
concentration are measured on what it leaves. Shares are of the excess mean square; they can
overlap (an edge pixel can be dark, a dark rim lie in one object) and need not add up to 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage

from sim_core.errors import InvalidInputError

__all__ = [
    "CONCENTRATION",
    "MIN_PIXELS",
    "MIN_SHARE",
    "Z_SIGNIFICANT",
    "Component",
    "Location",
    "dark_next_to_bright",
    "image_thirds",
    "locate_excess",
]

#: standard errors of the noise an offset or a concentration must stand out by
Z_SIGNIFICANT = 4.0
#: a set concentrates the excess when its share of it is at least this many times its pixel share
CONCENTRATION = 1.5
#: the share of the excess a component must hold to be named in the text
MIN_SHARE = 0.2
#: fewest compared pixels (overall, and in a region or set) a figure is taken over
MIN_PIXELS = 20

_THIRDS = (("upper", "middle", "lower"), ("left", "centre", "right"))


@dataclass(frozen=True)
class Component:
    """One shape of the excess: where, how much of it, and the residual's figures there.

    ``share``: of the excess mean square over all compared pixels; ``mean`` and ``rms``: the
    residual there (``mean`` before the common offset is taken out, for ``object`` after it;
    ``rms`` after it), ``noise_rms`` the noise image's there, in the location's ``unit``.
    """

    shape: str
    where: str
    share: float
    pixels: int
    mean: float
    rms: float
    noise_rms: float

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Location:
    """The residual's excess over the noise and its shapes (largest share first).

    ``components`` holds only those that stand out of the noise; empty when the excess does
    not (the residual is explained) or when no shape holds it (spread: see :meth:`text`).
    """

    unit: str
    pixels: int
    residual_rms: float
    noise_rms: float
    excess_ms: float
    components: tuple[Component, ...]

    @property
    def _spread(self) -> bool:
        # an excess beyond the noise's own spread of a mean square of this many pixels
        return self.excess_ms > Z_SIGNIFICANT * math.sqrt(2.0 / self.pixels) * self.noise_rms**2

    def named(self) -> tuple[Component, ...]:
        """The components the text names: those holding at least :data:`MIN_SHARE`."""
        return tuple(c for c in self.components if c.share >= MIN_SHARE)

    def text(self) -> str:
        """One line a person reads: the named shapes; else that the excess is spread (beyond
        the noise's own spread of a mean square), or that no shape stands out of the noise, or
        (no excess) that the residual is within the noise."""
        parts = [_describe(c, self.unit) for c in self.named()]
        if parts:
            return "; ".join(parts)
        rms = (f"rms {self.residual_rms:.3g} {self.unit} against {self.noise_rms:.3g} "
               f"{self.unit} of noise")
        if self._spread:
            return (f"spread over the compared pixels ({rms}), no offset, edge, dark-pixel or "
                    "image-region concentration")
        if self.excess_ms > 0.0:
            return f"no shape stands out of the noise ({rms})"
        return "within the noise"

    def to_dict(self) -> dict:
        return {"unit": self.unit, "pixels": self.pixels, "residual_rms": self.residual_rms,
                "noise_rms": self.noise_rms, "excess_ms": self.excess_ms,
                "components": [c.to_dict() for c in self.components], "text": self.text()}


def _describe(c: Component, unit: str) -> str:
    pct = f"{100.0 * c.share:.0f} % of the excess"
    if c.shape == "offset":
        return f"a common offset of {c.mean:+.3g} {unit} over {c.where} ({pct})"
    if c.shape == "object":
        return f"an offset of {c.mean:+.3g} {unit} on {c.where} ({pct})"
    # two-signed (mean well inside the rms: a shift or motion moves light both ways across an
    # edge) or one-signed (stray light brightens dark pixels, an object's own offset)
    sign = "two-signed" if abs(c.mean) < 0.5 * c.rms else f"one-signed, mean {c.mean:+.3g} {unit}"
    return (f"excess on {c.where}: {c.pixels} px hold {pct} (rms {c.rms:.3g} {unit} against "
            f"{c.noise_rms:.3g} {unit} of noise, {sign})")


def _check_image(name: str, a: np.ndarray, shape: tuple[int, ...] | None) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 2 or (shape is not None and a.shape != shape):
        raise InvalidInputError(name, f"got shape {a.shape}; allowed: a 2-D image of shape "
                                f"{shape if shape is not None else '(H, W)'}")
    return a


def locate_excess(
    residual: np.ndarray,
    noise: np.ndarray,
    mask: np.ndarray,
    *,
    unit: str,
    overall: str = "the compared pixels",
    regions: Mapping[str, np.ndarray] | None = None,
    sets: Mapping[str, np.ndarray] | None = None,
    z: float = Z_SIGNIFICANT,
) -> Location:
    """Take the residual's excess over the noise apart into its shapes.

    Parameters
    ----------
    residual, noise : (H, W) float
        Measured - fitted twin, and measured - second capture, in ``unit``; NaN where unknown.
    mask : (H, W) bool
        The compared pixels (intersected with where both images are finite).
    unit : str
        The images' unit, for the figures' text ("mm", "grey levels").
    overall : str
        What the mask covers, for the text ("the turntable objects").
    regions : {name: (H, W) bool}
        Named parts (objects) that may carry an offset of their own (shape ``object``) or hold
        the excess (shape ``on_object``).
    sets : {shape: (H, W) bool}
        Pixel sets the excess may concentrate on, keyed by shape; ``edges`` and ``dark`` read
        as silhouette edges and dark pixels next to bright ones; the image's thirds
        (:func:`image_thirds`) are always tried as shape ``region``.
    z : float
        Standard errors of the noise a figure must stand out by (> 0).

    Raises
    ------
    InvalidInputError
        Images of different shapes or not 2-D, a ``z`` not finite and > 0, or fewer than
        :data:`MIN_PIXELS` compared pixels (field ``mask``).
    """
    r_img = _check_image("residual", residual, None).astype(float)
    shape = r_img.shape
    n_img = _check_image("noise", noise, shape).astype(float)
    m = _check_image("mask", mask, shape).astype(bool) & np.isfinite(r_img) & np.isfinite(n_img)
    if not (math.isfinite(z) and z > 0.0):
        raise InvalidInputError("z", f"got {z!r}; allowed: a finite number > 0")
    count = int(m.sum())
    if count < MIN_PIXELS:
        raise InvalidInputError(
            "mask", f"{count} pixels finite in both images; allowed: at least {MIN_PIXELS}")
    r, n = r_img[m], n_img[m]
    ms_n = float(np.mean(n**2))
    excess = float(np.mean(r**2)) - ms_n
    out = {"unit": unit, "pixels": count, "residual_rms": math.sqrt(float(np.mean(r**2))),
           "noise_rms": math.sqrt(ms_n), "excess_ms": excess}
    # No excess, or a noise-free pair (identical captures): nothing to take apart. The noise's
    # variance is the scale of every test below, a zero one would make every offset significant.
    if not (excess > 0.0 and ms_n > 0.0):
        return Location(components=(), **out)
    found: list[Component] = []

    def offset(shape_name: str, where: str, sel: np.ndarray, values: np.ndarray) -> float:
        k = int(sel.sum())
        if k < MIN_PIXELS:
            return 0.0
        b = float(np.mean(values[sel]))
        # the standard error of a mean of k pixels of the noise's spread
        if abs(b) <= z * math.sqrt(ms_n / k):
            return 0.0
        found.append(Component(shape_name, where, k * b * b / (count * excess), k, b,
                                math.sqrt(float(np.mean(values[sel] ** 2))),
                                math.sqrt(float(np.mean(n[sel] ** 2)))))
        return b

    everywhere = np.ones(count, bool)
    after_common = r - offset("offset", overall, everywhere, r)
    with_offset = set()
    for name, region in (regions or {}).items():
        sel = _check_image(f"regions[{name!r}]", region, shape).astype(bool)[m]
        if offset("object", name, sel, after_common) != 0.0:
            with_offset.add(name)

    # Per-pixel excess of what the common offset leaves (a region's offset may be the very
    # concentration a set shows: a dark rim inside one object); under "explained" its sum over a
    # set of k pixels is 0 give or take sqrt(2 k) times the spread of n^2 (two independent
    # squares).
    e = after_common**2 - n**2
    spread = float(np.std(n**2))
    tried = dict(sets or {})
    # an object whose offset is named already is not named again for the same excess
    tried.update({f"on_object:{k}": v for k, v in (regions or {}).items()
                  if k not in with_offset})
    tried.update({f"region:{k}": v for k, v in image_thirds(shape).items()})
    for key, pixels in tried.items():
        sel = _check_image(f"sets[{key!r}]", pixels, shape).astype(bool)[m]
        k = int(sel.sum())
        if k < MIN_PIXELS or k == count:
            continue
        total = float(np.sum(e[sel]))
        share = total / (count * excess)
        if total <= z * math.sqrt(2.0 * k) * spread or share < CONCENTRATION * k / count:
            continue
        shape_name, where = _set_name(key)
        found.append(Component(shape_name, where, share, k, float(np.mean(r[sel])),
                               math.sqrt(float(np.mean(after_common[sel] ** 2))),
                               math.sqrt(float(np.mean(n[sel] ** 2)))))
    found.sort(key=lambda c: -c.share)
    return Location(components=tuple(found), **out)


def _set_name(key: str) -> tuple[str, str]:
    if key.startswith("region:"):
        return "region", f"the {key.removeprefix('region:')} of the image"
    if key.startswith("on_object:"):
        return "on_object", key.removeprefix("on_object:")
    return key, {"edges": "silhouette edges",
                 "dark": "dark pixels next to bright ones"}.get(key, key)


def image_thirds(shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """The image cut in thirds across and down: nine masks named "upper left" ... "lower right"
    ("middle centre" is "centre").

    >>> sorted(image_thirds((6, 6)))[:3]
    ['centre', 'lower centre', 'lower left']
    >>> int(image_thirds((6, 6))["upper left"].sum())
    4
    """
    h, w = shape
    rows = np.array_split(np.arange(h), 3)
    cols = np.array_split(np.arange(w), 3)
    out = {}
    for i, rname in enumerate(_THIRDS[0]):
        for j, cname in enumerate(_THIRDS[1]):
            sel = np.zeros(shape, bool)
            sel[np.ix_(rows[i], cols[j])] = True
            name = "centre" if (rname, cname) == ("middle", "centre") else f"{rname} {cname}"
            out[name] = sel
    return out


def dark_next_to_bright(amplitude: np.ndarray, valid: np.ndarray, radius_px: float = 30.0,
                        ratio: float = 0.5) -> np.ndarray:
    """Pixels whose amplitude is below ``ratio`` times the mean amplitude around them (a
    Gaussian of ``radius_px`` over the valid pixels): where a little of the bright neighbours'
    light (stray light) weighs most, (H, W) bool.

    >>> a = np.ones((9, 9)); a[:, :5] = 0.1  # dark on the left, bright on the right
    >>> dark_next_to_bright(a, np.ones((9, 9), bool), radius_px=1.0)[4].astype(int).tolist()
    [0, 0, 0, 0, 1, 0, 0, 0, 0]
    """
    a = _check_image("amplitude", amplitude, None).astype(float)
    ok = _check_image("valid", valid, a.shape).astype(bool) & np.isfinite(a)
    if not (math.isfinite(radius_px) and 0.0 < radius_px <= 1000.0):
        raise InvalidInputError("radius_px", f"got {radius_px!r}; allowed: 0 < radius <= 1000 px")
    if not (math.isfinite(ratio) and 0.0 < ratio < 1.0):
        raise InvalidInputError("ratio", f"got {ratio!r}; allowed: 0 < ratio < 1")
    a0 = np.where(ok, np.maximum(a, 0.0), 0.0)
    weight = ndimage.gaussian_filter(ok.astype(float), radius_px, mode="constant")
    around = ndimage.gaussian_filter(a0, radius_px, mode="constant")
    # the local mean over valid pixels; where no valid pixel is near (weight 0) nothing is dark
    mean = np.divide(around, weight, out=np.zeros_like(around), where=weight > 1e-12)
    return ok & (a0 < ratio * mean)
