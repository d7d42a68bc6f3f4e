"""The Table 3 reproduction committed in docs/brdf-fitting.md is what the code produces.

The fits' last digits depend on the CPU (numpy's vectorised loops sum in another order with
AVX-512 than with AVX2, and the optimiser's path follows), so the committed table is compared
with the code's cell by cell, each number within the precision it is printed to: one unit in its
last printed digit (two printings of values that differ by less than that can differ by one
unit), and a fitted parameter within the larger of that and the fit's own 1-sigma uncertainty (a
parameter the data do not determine, ``U``, has an infinite one). The words, the outlier flags,
the determined/undetermined marks and the outlier counts must be equal.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from calibration.brdf.table3 import MATERIALS, fit_table3, table3_markdown

DOC = Path(__file__).resolve().parents[3] / "docs" / "brdf-fitting.md"
IMAGE = DOC.parent / "images" / "brdf-table3.png"
NUMBER = re.compile(r"^-?\d+(?:\.(\d+))?$")
PARAMETERS = ("kd", "ks", "m", "n2")


def _committed() -> str:
    text = DOC.read_text(encoding="utf-8")
    block = re.search(r"<!-- table3:begin -->\n(.*?)<!-- table3:end -->", text, re.S)
    assert block, "docs/brdf-fitting.md lacks the table3 markers"
    return block.group(1)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _unit(text: str) -> float:
    """One unit in the last printed digit of ``text`` (a number as printed)."""
    decimals = NUMBER.match(text).group(1)
    return 10.0 ** -len(decimals) if decimals else 1.0


def _split(cell: str) -> tuple[str, str]:
    """``'0.0039 (outlier)'`` -> ``('0.0039', '(outlier)')``; ``'1.67 %'`` -> ``('1.67', '%')``."""
    head, _, tail = cell.partition(" ")
    return head, tail


def _within(committed: str, computed: str, tolerance: float, where: str) -> None:
    a, b = float(committed), float(computed)
    assert abs(a - b) <= tolerance + 1e-12, (
        f"{where}: committed {committed}, computed {computed} (allowed difference {tolerance:g}); "
        "regenerate with `python -m calibration.brdf.table3` if the code changed")


def compare_tables(committed: str, computed: str, sigma: dict[str, dict[str, float]]) -> None:
    """Assert the two markdown tables agree as the module docstring says.

    ``sigma``: each fit's (key as in the parameter table) 1-sigma uncertainty per parameter.
    """
    old, new = committed.splitlines(), computed.splitlines()
    assert len(old) == len(new), "the table's rows changed: regenerate it"
    header = None
    for i, (line_old, line_new) in enumerate(zip(old, new, strict=True)):
        if not line_old.startswith("| ") or line_old.startswith("|---"):
            assert line_old == line_new, f"line {i + 1} differs"
            continue
        cells_old, cells_new = _cells(line_old), _cells(line_new)
        if not NUMBER.match(_split(cells_old[-1])[0]) and cells_old[-1] != "-":
            header = cells_old
            assert cells_old == cells_new, f"header of line {i + 1} differs"
            continue
        assert len(cells_old) == len(cells_new), f"line {i + 1}: the number of cells differs"
        key = cells_old[0]
        for j, (a, b) in enumerate(zip(cells_old, cells_new, strict=True)):
            where = f"line {i + 1} ({key}), column {header[j]!r}"
            (num_a, tail_a), (num_b, tail_b) = _split(a), _split(b)
            if not NUMBER.match(num_a):
                assert a == b, where
                continue
            assert tail_a == tail_b, f"{where}: {a!r} against {b!r}"
            assert NUMBER.match(num_b), f"{where}: {b!r} is not a number"
            tolerance = _unit(num_a)
            if header[j] in PARAMETERS:
                tolerance = max(tolerance, sigma[key][header[j]])
            elif "err %" in header[j] and not header[j].startswith("paper"):
                # a relative error printed to 0.1 % of a value printed to 1e-4 [1/sr]: the
                # value's unit, relative to the measurement, is the error's resolution too
                measured = float(_split(cells_old[header.index("measured")])[0])
                tolerance += 100.0 * 1e-4 / measured
            _within(num_a, num_b, tolerance, where)


@pytest.mark.slow
def test_committed_table_matches_the_code():
    rows, fits = fit_table3()
    sigma = {key: {p: float(fit.uncertainty.get(p, math.inf)) for p in PARAMETERS}
             for key, fit in fits.items()}
    compare_tables(_committed(), table3_markdown(rows, fits), sigma)
    assert IMAGE.is_file()
    # the measured points are the paper's 48 (54 less the six '-')
    assert sum(np.isfinite(r.measured) for r in rows) == 48
    assert {r.material for r in rows} == set(MATERIALS)
    # the white tile, which Cook-Torrance describes well, is fitted within 21 % everywhere
    white = [r for r in rows if r.material == "white-matte-tile" and np.isfinite(r.measured)]
    assert max(r.ours_all_angles_error_percent for r in white) < 21.0


# -- the comparison itself, on the committed table (fast) ---------------------------------------
def _sigma_of(table: str, value: float) -> dict[str, dict[str, float]]:
    keys = [cells[0] for cells in map(_cells, table.splitlines())
            if len(cells) == 7 and cells[5].endswith(" %")]
    return {k: dict.fromkeys(PARAMETERS, value) for k in keys}


def test_the_committed_table_agrees_with_itself():
    table = _committed()
    compare_tables(table, table, _sigma_of(table, 0.0))


def test_a_last_digit_that_flips_is_accepted_but_two_units_are_not():
    table = _committed()
    one = table.replace("| 0.4052 | 0.3651 |", "| 0.4052 | 0.3652 |", 1)
    assert one != table
    compare_tables(table, one, _sigma_of(table, 0.0))
    two = table.replace("| 0.4052 | 0.3651 |", "| 0.4052 | 0.3653 |", 1)
    with pytest.raises(AssertionError, match="paper model"):
        compare_tables(table, two, _sigma_of(table, 0.0))


def test_a_parameter_may_move_within_its_uncertainty_only():
    table = _committed()
    moved = table.replace("| black-protective-shield@40 | 0.000 U | 0.562 U |",
                          "| black-protective-shield@40 | 0.000 U | 0.572 U |", 1)
    assert moved != table
    compare_tables(table, moved, _sigma_of(table, 0.02))
    with pytest.raises(AssertionError, match="ks"):
        compare_tables(table, moved, _sigma_of(table, 0.001))


def test_a_changed_flag_or_mark_is_refused():
    table = _committed()
    for old, new in (("0.0039 (outlier)", "0.0039"), ("0.159 D", "0.159 U")):
        changed = table.replace(old, new, 1)
        assert changed != table
        with pytest.raises(AssertionError):
            compare_tables(table, changed, _sigma_of(table, math.inf))
