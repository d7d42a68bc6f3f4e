"""The fittable material kinds: free parameters, physical bounds, and evaluation.

Every kind of :mod:`sim_core.materials` that can be fitted to goniometer data is described by a
:class:`FitModel`: its numeric parameters with the bounds the fit searches (the constructor's
own ranges, which are the papers' physical bounds), the pair whose sum is limited to 1 (energy
conservation) and the non-numeric options the fit keeps fixed. A model is evaluated by building
the material with :func:`sim_core.materials.make_material` and calling its ``eval_local``: the
same compiled kernel the renderer calls, so a fit and a rendering cannot disagree.

:class:`FreeParameters` splits a model's parameters into the fitted ones and those a caller pins
(``fixed``), and maps the free ones between the *native* vector (the parameters themselves,
searched by differential evolution with a linear constraint) and the *internal* vector of the
least-squares refinement, where the constrained pair ``(a, b)`` with ``a + b <= 1`` becomes the
box-bounded ``(a + b, b / (a + b))``.

Bounds
------
- ``cook-torrance`` (relay-wall paper, its GA bounds in Section 3): ``kd, ks`` in [0, 1] with
  ``kd + ks <= 1``, ``m`` in [1e-6, 1] (the paper's [0, 1]; ``m = 0`` is a mirror the model
  cannot evaluate), ``n2`` in [1, 3]. Fresnel at the incidence angle, ``F(θi)`` as the paper's
  eqs. (7), (8) and (12) print it.
- ``seed-microfacet`` (seed eqs. (9)-(10), the ranges of ``SeedMicrofacet``): ``ks, kd`` in
  [0, 1] with ``ks + kd <= 1``, ``fresnel_exponent`` in [0, 100], ``sigma`` in [1e-6, 1],
  ``f0`` in [0, 1].
- ``lambertian``: ``albedo`` in [0, 1].
- ``hapke`` (SLIM eq. (11), the ranges of ``Hapke``): ``w`` in [0, 1], ``b0`` in [0, 2],
  ``h`` in [0, 1], ``phase_b`` in [-1, 1]; parameter sets that reflect more than they receive
  are rejected by the constructor and count as infeasible.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.materials import Material, make_material

__all__ = ["FIT_MODELS", "FitModel", "FreeParameters", "ParameterSpec", "fit_model"]


@dataclass(frozen=True)
class ParameterSpec:
    """One numeric parameter of a model.

    Attributes
    ----------
    name : str
        The constructor's keyword.
    lower, upper : float
        Physical bounds the fit searches (inclusive).
    resolution : float
        Absolute size below which a difference does not matter; the floor of the scale a
        parameter's uncertainty is compared with when deciding whether it was determined (a
        parameter whose value is ~0, e.g. ``kd`` of a black surface, is judged against it).
    """

    name: str
    lower: float
    upper: float
    resolution: float


@dataclass(frozen=True)
class FitModel:
    """A fittable material kind.

    Attributes
    ----------
    kind : str
        The material kind of :data:`sim_core.materials.MATERIAL_KINDS`.
    parameters : tuple of ParameterSpec
        The numeric parameters, in the order of the fit vectors.
    sum_limited : tuple of two names, optional
        A pair whose sum is at most 1.
    options : mapping
        Non-numeric constructor arguments the fit keeps at these values.
    """

    kind: str
    parameters: tuple[ParameterSpec, ...]
    sum_limited: tuple[str, str] | None = None
    options: Mapping[str, Any] = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def spec(self, name: str) -> ParameterSpec:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)

    def build(self, values: Mapping[str, float]) -> Material:
        """The material with these parameter values (and the model's options).

        Raises
        ------
        InvalidInputError
            For values the constructor rejects (out of range, energy condition).
        """
        return make_material(self.kind, **dict(self.options), **{k: float(v)
                                                                 for k, v in values.items()})

    def evaluate(self, values: Mapping[str, float], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """BRDF [1/sr] at the direction pairs ``(wi, wo)`` (shading frame), via ``eval_local``."""
        return self.build(values).eval_local(wi, wo)


FIT_MODELS: Mapping[str, FitModel] = MappingProxyType({
    "seed-microfacet": FitModel(
        "seed-microfacet",
        (
            ParameterSpec("ks", 0.0, 1.0, 0.01),
            ParameterSpec("kd", 0.0, 1.0, 0.01),
            ParameterSpec("fresnel_exponent", 0.0, 100.0, 0.1),
            ParameterSpec("sigma", 1e-6, 1.0, 1e-3),
            ParameterSpec("f0", 0.0, 1.0, 0.01),
        ),
        sum_limited=("kd", "ks"),
    ),
    "cook-torrance": FitModel(
        "cook-torrance",
        (
            ParameterSpec("kd", 0.0, 1.0, 0.01),
            ParameterSpec("ks", 0.0, 1.0, 0.01),
            ParameterSpec("m", 1e-6, 1.0, 1e-3),
            ParameterSpec("n2", 1.0, 3.0, 0.01),
        ),
        sum_limited=("kd", "ks"),
        options=MappingProxyType({"fresnel_angle": "incidence"}),
    ),
    "lambertian": FitModel("lambertian", (ParameterSpec("albedo", 0.0, 1.0, 0.01),)),
    "hapke": FitModel(
        "hapke",
        (
            ParameterSpec("w", 0.0, 1.0, 0.01),
            ParameterSpec("b0", 0.0, 2.0, 0.05),
            ParameterSpec("h", 0.0, 1.0, 0.01),
            ParameterSpec("phase_b", -1.0, 1.0, 0.05),
        ),
    ),
})


def fit_model(kind: str) -> FitModel:
    """The :class:`FitModel` of ``kind``; an input error listing the fittable kinds otherwise."""
    model = FIT_MODELS.get(kind) if isinstance(kind, str) else None
    if model is None:
        raise InvalidInputError(
            "model", f"{kind!r} is not a fittable material kind; allowed: {', '.join(FIT_MODELS)}")
    return model


class FreeParameters:
    """The parameters a fit varies, given those the caller pins.

    Parameters
    ----------
    model : FitModel
    fixed : mapping, optional
        ``name -> value`` of parameters held at the given value.

    Raises
    ------
    InvalidInputError
        ``fixed`` names an unknown parameter, a value outside its bounds, a pinned pair whose
        sum exceeds 1, or pins every parameter.
    """

    def __init__(self, model: FitModel, fixed: Mapping[str, float] | None = None) -> None:
        self.model = model
        fixed = dict(fixed or {})
        for name, value in fixed.items():
            if name not in model.names:
                raise InvalidInputError(
                    "fixed", f"{name!r} is not a parameter of {model.kind}; allowed: "
                             f"{', '.join(model.names)}")
            spec = model.spec(name)
            v = float(value)
            if not (np.isfinite(v) and spec.lower <= v <= spec.upper):
                raise InvalidInputError(
                    f"fixed.{name}", f"{name} = {value!r} is outside [{spec.lower:g}, "
                                     f"{spec.upper:g}] ({model.kind})")
            fixed[name] = v
        pair = model.sum_limited
        if pair and all(p in fixed for p in pair) and fixed[pair[0]] + fixed[pair[1]] > 1 + 1e-12:
            raise InvalidInputError(
                f"fixed.{pair[1]}", f"{pair[0]} + {pair[1]} = {fixed[pair[0]] + fixed[pair[1]]:g}"
                                    f" exceeds 1 ({model.kind})")
        if pair:  # a partner pinned at 1 leaves its free partner no room: pin that at 0
            for a, b in (pair, pair[::-1]):
                if a in fixed and b not in fixed and fixed[a] >= 1.0 - 1e-12:
                    fixed[b] = model.spec(b).lower
        self.fixed: dict[str, float] = fixed
        self.names: tuple[str, ...] = tuple(n for n in model.names if n not in fixed)
        if not self.names:
            raise InvalidInputError("fixed", f"pins every parameter of {model.kind}: nothing to "
                                             f"fit")
        #: the constrained pair as indices into the free vector, when both are free
        self._pair: tuple[int, int] | None = None
        if pair and all(p in self.names for p in pair):
            self._pair = (self.names.index(pair[0]), self.names.index(pair[1]))

    def __len__(self) -> int:
        return len(self.names)

    # native vectors ------------------------------------------------------------------------
    def bounds(self) -> list[tuple[float, float]]:
        """Native bounds of the free parameters; a free partner of a pinned sum-limited
        parameter has its upper bound lowered to ``1 - pinned``."""
        out = []
        pair = self.model.sum_limited
        for name in self.names:
            spec = self.model.spec(name)
            hi = spec.upper
            if pair and name in pair:
                other = pair[1] if name == pair[0] else pair[0]
                if other in self.fixed:
                    hi = min(hi, 1.0 - self.fixed[other])
            out.append((spec.lower, hi))
        return out

    def constraint_matrix(self) -> np.ndarray | None:
        """Row ``A`` with ``A @ x <= 1`` for the free constrained pair, or None."""
        if self._pair is None:
            return None
        a = np.zeros((1, len(self.names)))
        a[0, list(self._pair)] = 1.0
        return a

    def values(self, x: np.ndarray) -> dict[str, float]:
        """All parameter values (free from ``x``, pinned from ``fixed``), in model order."""
        free = dict(zip(self.names, (float(v) for v in x), strict=True))
        return {n: free[n] if n in free else self.fixed[n] for n in self.model.names}

    def clip(self, x: np.ndarray) -> np.ndarray:
        """``x`` moved into the bounds and onto the constraint where it strays by rounding."""
        lo, hi = np.array(self.bounds()).T
        x = np.clip(np.asarray(x, dtype=np.float64), lo, hi)
        if self._pair is not None:
            i, j = self._pair
            total = x[i] + x[j]
            if total > 1.0:
                x[i], x[j] = x[i] / total, x[j] / total
        return x

    def build(self, x: np.ndarray) -> Material:
        return self.model.build(self.values(x))

    # internal vectors of the least-squares refinement --------------------------------------
    def to_internal(self, x: np.ndarray) -> np.ndarray:
        """``(a, b) -> (a + b, b / (a + b))`` for the constrained pair; identity otherwise."""
        u = np.array(x, dtype=np.float64)
        if self._pair is not None:
            i, j = self._pair
            total = x[i] + x[j]
            u[i] = min(total, 1.0)
            u[j] = x[j] / total if total > 0 else 0.5
        return u

    def from_internal(self, u: np.ndarray) -> np.ndarray:
        x = np.array(u, dtype=np.float64)
        if self._pair is not None:
            i, j = self._pair
            x[i] = u[i] * (1.0 - u[j])
            x[j] = u[i] * u[j]
        return x

    def internal_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = np.array(self.bounds(), dtype=np.float64).T
        if self._pair is not None:
            for k in self._pair:
                lo[k], hi[k] = 0.0, 1.0
        return lo, hi
