"""Verdicts: what an estimator may say of each key it estimates.

Every estimate of a calibration or an object fit carries one of three verdicts, so that no
number leaves the project with error bars it has not earned:

- ``determined``: the fit explains its data (its residual is what the noise makes) and the
  key's standard deviation is within the key's limit; ``std`` is that standard deviation, never
  smaller than the residual supports (:func:`honest_std`).
- ``not determined``: the data do not pin the key down (its standard deviation is above the
  key's limit, too few views or pixels, a direction the plan cannot see); the file keeps the
  prior or nominal value, ``reason`` says why.
- ``unexplained``: the model does not explain the data that drive the key (a reduced chi-square
  well above what the noise allows, views that disagree beyond their errors); ``reason`` says
  where and by how much. The estimate is printed but must not be trusted.

A procedure builds a :class:`Verdicts` (a flat mapping from each key, named as in the file it
writes, ``camera.fx_px``, ``mount.pose_offset.position_m``, ``objects.body.reflectance_scale``,
to its :class:`Verdict`), and the command writes it next to the file as ``verdicts.json``
(:func:`write_verdicts`).

The goodness of fit is judged by the reduced chi-square ``chi2 / dof`` of whitened residuals:
for a model that explains the data its expectation is 1 with a standard deviation of
``sqrt(2 / dof)``; :data:`CHI2_UNEXPLAINED` is the value above which a residual is read as model
error rather than noise, however many residuals there are (with 10^5 residuals 1.05 is already
significant, but a 5 % excess of variance is the size of the noise model's own uncertainty).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np

from sim_core.files import atomic_write
from sim_core.json_safe import json_safe

VerdictName = Literal["determined", "not determined", "unexplained"]
VERDICTS: tuple[VerdictName, ...] = ("determined", "not determined", "unexplained")
#: reduced chi-square above which a fit's residual is model error, not noise (module docstring)
CHI2_UNEXPLAINED = 2.0
#: the file a command writes beside its calibration or object file
VERDICTS_FILE = "verdicts.json"

Std = float | list[float] | None
#: a group of residuals (a view's name or index, a slice)
K = TypeVar("K")


@dataclass(frozen=True)
class Verdict:
    """One key's verdict, its standard deviation (a number, one per component, or None) in the
    key's unit, and why (None for a plain ``determined``)."""

    verdict: VerdictName
    std: Std = None
    reason: str | None = None

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict: got {self.verdict!r}; allowed: {', '.join(VERDICTS)}")
        if self.verdict != "determined" and not self.reason:
            raise ValueError(f"a {self.verdict!r} verdict needs its reason")

    @property
    def determined(self) -> bool:
        return self.verdict == "determined"

    def to_json(self) -> dict[str, Any]:
        return json_safe({"verdict": self.verdict, "std": self.std, "reason": self.reason},
                         non_finite=None)


class Verdicts(Mapping[str, Verdict]):
    """The verdicts of one procedure's keys, in the order they were judged."""

    def __init__(self, items: Mapping[str, Verdict] | None = None) -> None:
        self._items: dict[str, Verdict] = dict(items or {})

    def __getitem__(self, key: str) -> Verdict:
        return self._items[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"Verdicts({self.counts()})"

    def add(self, key: str, verdict: Verdict) -> None:
        """Judge ``key`` (once: a key judged twice is a bug of the procedure)."""
        if key in self._items:
            raise ValueError(f"{key}: judged twice")
        self._items[key] = verdict

    def update_from(self, other: Mapping[str, Verdict], prefix: str = "") -> None:
        """Add every verdict of ``other``, its keys under ``prefix`` (``"camera."``)."""
        for key, verdict in other.items():
            self.add(prefix + key, verdict)

    def counts(self) -> dict[str, int]:
        """How many keys have each verdict."""
        return {v: sum(1 for x in self._items.values() if x.verdict == v) for v in VERDICTS}

    def to_json(self) -> dict[str, dict[str, Any]]:
        return {key: v.to_json() for key, v in self._items.items()}

    @classmethod
    def from_json(cls, data: Mapping[str, Mapping[str, Any]]) -> Verdicts:
        return cls({k: Verdict(v["verdict"], v.get("std"), v.get("reason"))
                    for k, v in data.items()})


def honest_std(std: float, reduced_chi2: float) -> float:
    """The standard deviation a fit may claim: its statistical one (from the whitened
    Jacobian, which assumes the residual is noise) scaled by ``sqrt(reduced_chi2)`` when the
    residual is larger than the noise (never scaled down: a residual smaller than the noise
    model says does not make the estimate better than its noise)."""
    if not math.isfinite(std) or not math.isfinite(reduced_chi2):
        return math.inf
    return std * math.sqrt(max(1.0, reduced_chi2))


def judge(
    std: float | Sequence[float],
    limit: float,
    *,
    reduced_chi2: float = 1.0,
    spread: float | Sequence[float] | None = None,
    chi2_limit: float = CHI2_UNEXPLAINED,
    unit: str = "",
    where: str = "the fit",
) -> Verdict:
    """The verdict of a key with standard deviation ``std`` (one per component: the largest
    counts) against ``limit``, from a fit whose residual has ``reduced_chi2``.

    ``std`` is taken as the fit's statistical one and made honest (:func:`honest_std`) first;
    ``spread`` (same shape), the estimate's spread over views or resamples (a jackknife, a
    bootstrap), is a floor under it: the views' disagreement is an error the noise model may
    not know. Unexplained beats not determined: a fit that does not explain its data says so
    whatever its error bars; ``where`` names the data in the reason (``"views +30, -80 deg"``).
    """
    scalar = isinstance(std, int | float)
    stds = [float(std)] if scalar else [float(s) for s in std]
    if spread is None:
        floors = [0.0] * len(stds)
    else:
        floors = [float(spread)] if isinstance(spread, int | float) else [float(s) for s in spread]
        if len(floors) != len(stds):
            raise ValueError(f"spread: {len(floors)} values for {len(stds)} standard deviations")
    honest = [max(honest_std(s, reduced_chi2), f if not math.isnan(f) else math.inf)
              for s, f in zip(stds, floors, strict=True)]
    reported: Std = honest[0] if scalar else honest
    worst = max(honest) if honest else math.inf
    if not math.isfinite(reduced_chi2) or reduced_chi2 > chi2_limit:
        chi2_txt = f"{reduced_chi2:.3g}" if math.isfinite(reduced_chi2) else "not finite"
        return Verdict("unexplained", reported,
                       f"{where}: reduced chi-square {chi2_txt} after the fit, above "
                       f"{chi2_limit:g} (noise explains about 1): the model does not explain "
                       "these data")
    if not math.isfinite(worst) or worst > limit:
        if not math.isfinite(worst):
            return Verdict("not determined", None, "its error is unbounded: the data do not "
                           f"pin it down (the limit is {limit:g}{unit})")
        return Verdict("not determined", reported,
                       f"standard deviation {worst:.3g}{unit} above the limit {limit:g}{unit}")
    return Verdict("determined", reported)


def write_verdicts(path: str | Path, verdicts: Verdicts) -> Path:
    """The flat mapping key -> ``{verdict, std, reason}`` at ``path`` (a command's
    ``DIR/verdicts.json``, :data:`VERDICTS_FILE`, or :func:`verdicts_beside` its output file),
    written whole or not at all."""
    path = Path(path)
    text = json.dumps(verdicts.to_json(), indent=2, allow_nan=False) + "\n"
    atomic_write(path, text.encode())
    return path


def read_verdicts(path: str | Path) -> Verdicts:
    """The verdicts a command wrote (:func:`write_verdicts`)."""
    return Verdicts.from_json(json.loads(Path(path).read_text(encoding="utf-8")))


def chi2_limit_for(dof: int, limit: float = CHI2_UNEXPLAINED, tail: float = 1e-3) -> float:
    """The reduced chi-square above which a fit with ``dof`` degrees of freedom does not
    explain its data: :data:`CHI2_UNEXPLAINED`, or, when few residuals make the chi-square
    itself noisy (its standard deviation is ``sqrt(2 / dof)``), the value noise exceeds with
    probability ``tail`` only (the chi-square distribution's quantile over ``dof``): 3.5 at 7
    degrees of freedom, :data:`CHI2_UNEXPLAINED` from about 60 on. No degree of freedom: inf
    (nothing to judge by; the caller says so)."""
    from scipy.stats import chi2

    if dof < 1:
        return math.inf
    return max(limit, float(chi2.isf(tail, dof)) / dof)


def above_limit(chi2_by_group: Mapping[K, float], limit: float = CHI2_UNEXPLAINED) -> list[K]:
    """The groups (views, slices) whose reduced chi-square is above ``limit``, worst first; one
    that is not finite counts as above every other.

    >>> above_limit({"+30": 1.1, "-80": 4.2, "0": float("nan"), "+60": 2.5})
    ['0', '-80', '+60']
    """
    def badness(group: K) -> float:
        c = chi2_by_group[group]
        return c if math.isfinite(c) else math.inf

    return sorted((g for g, c in chi2_by_group.items() if not c <= limit), key=badness,
                  reverse=True)


def jackknife_covariance_of(leave_one_out: np.ndarray) -> np.ndarray:
    """The delete-one-group jackknife covariance (Efron and Stein) of an estimate from its ``g``
    leave-one-out values, the rows of ``leave_one_out`` (g, n): ``(g - 1) / g * sum_i (x_i -
    mean)(x_i - mean)^T``; inf everywhere with fewer than two (one has no spread).

    >>> jackknife_covariance_of(np.array([[1.0], [3.0]])).tolist()
    [[1.0]]
    """
    x = np.asarray(leave_one_out, dtype=np.float64)
    n = x.shape[1] if x.ndim == 2 else 1
    if x.ndim != 2 or x.shape[0] < 2:
        return np.full((n, n), np.inf)
    d = x - x.mean(axis=0)
    return (x.shape[0] - 1) / x.shape[0] * d.T @ d


def verdicts_beside(out: str | Path) -> Path:
    """Where a command whose output is one file writes its verdicts: beside it, the file's name
    without its suffix and ``.verdicts.json`` (``sample.yaml`` -> ``sample.verdicts.json``).

    >>> verdicts_beside("out/sample.yaml").as_posix()
    'out/sample.verdicts.json'
    """
    path = Path(out)
    return path.with_name(path.stem + ".verdicts.json")


def count_line(verdicts: Verdicts) -> str:
    """The counts in one line: ``"25 keys: 22 determined, 1 not determined, 2 unexplained"``."""
    c = verdicts.counts()
    return f"{len(verdicts)} keys: " + ", ".join(f"{c[v]} {v}" for v in VERDICTS)


def verdict_lines(verdicts: Verdicts) -> list[str]:
    """What a command prints of its verdicts: :func:`count_line`, then every key that is not
    determined or unexplained with its verdict and reason."""
    return [count_line(verdicts)] + [f"  {key}: {v.verdict}: {v.reason}"
                                     for key, v in verdicts.items() if not v.determined]


__all__ = ["CHI2_UNEXPLAINED", "VERDICTS", "VERDICTS_FILE", "Verdict", "VerdictName", "Verdicts",
           "above_limit", "chi2_limit_for", "count_line", "honest_std", "jackknife_covariance_of",
           "judge", "read_verdicts",
           "verdict_lines", "verdicts_beside", "write_verdicts"]
