"""``toftwin compare``: the depth difference, flying and invalid pixels, and the seed's Table 5
rows for a measured and a simulated frame folder."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from service.cli import ranges
from service.cli.common import console, number_option, print_error
from sim_core.errors import InvalidInputError


def compare(
    measured_dir: Annotated[Path, typer.Argument(help="Measured frame folder (raw.npz).")],
    simulated_dir: Annotated[Path, typer.Argument(help="Simulated frame folder (frame.npz).")],
    mask: Annotated[
        str, typer.Option(help="turntable, objects, depth_window, region or all.")
    ] = "turntable",
    objects: Annotated[
        str | None, typer.Option(help="Comma-separated object names (--mask objects).")
    ] = None,
    near_m: Annotated[
        float | None, number_option("--near-m", help="Window start [m].",
                                    allowed=ranges.MASK_DISTANCE)
    ] = None,
    far_m: Annotated[
        float | None, number_option("--far-m", help="Window end [m].",
                                    allowed=ranges.MASK_DISTANCE)
    ] = None,
    rows: Annotated[str | None, typer.Option(help="Region rows START:STOP.")] = None,
    cols: Annotated[str | None, typer.Option(help="Region cols START:STOP.")] = None,
    out: Annotated[Path, typer.Option("--out", help="JSON file to write.")] = Path(
        "comparison.json"),
) -> None:
    """Table 5 (mean, variance, MSE, SSIM, PSNR of grey and depth) of two frame folders."""
    from pydantic import ValidationError

    from service.lab.comparison import build_mask, load_measured, load_simulated
    from service.lab.comparison import compare as compare_images
    from service.lab.requests import MaskSpec
    from sim_core.metrics import TABLE_HEADER

    try:
        spec = MaskSpec(kind=mask, names=objects.split(",") if objects else None,
                        near_m=near_m, far_m=far_m, rows=_pair("--rows", rows),
                        cols=_pair("--cols", cols))
        measured = load_measured(measured_dir)
        simulated = load_simulated(simulated_dir)
        m = build_mask(spec, measured.image, simulated.arrays.get("object_id"),
                       simulated.meta.get("object_names", []),
                       simulated.meta.get("turntable_object_ids", []))
        report = compare_images(measured.image, simulated.image, m,
                                (measured.grey_full_scale, simulated.grey_full_scale))
    except ValidationError as exc:
        e = exc.errors()[0]
        option = {"names": "--objects", "near_m": "--near-m", "far_m": "--far-m",
                  "rows": "--rows", "cols": "--cols"}.get(str(e["loc"][0]) if e["loc"] else "",
                                                          "--mask")
        print_error(f"{option}: {e['msg']}")
        raise typer.Exit(code=2) from None
    except InvalidInputError as exc:
        print_error(str(exc))
        raise typer.Exit(code=2) from None
    for line in report.tof.summary_lines():  # what a ToF engineer reads first
        console.print(line, markup=False, highlight=False)
    table = Table(*TABLE_HEADER, title=f"{measured_dir} vs {simulated_dir} ({mask} mask, "
                  f"{report.n_pixels} pixels)")
    for row in report.table_rows():
        table.add_row(*row)
    console.print(table)
    data = {"measured_dir": str(measured_dir), "simulated_dir": str(simulated_dir),
            "mask": spec.model_dump(mode="json"), "metrics": report.to_dict(),
            "table": [list(r) for r in report.table_rows()]}
    out.write_text(json.dumps(data, indent=2, allow_nan=False))
    console.print(f"wrote {out}")


def _pair(name: str, text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise InvalidInputError(name, f"got {text!r}; allowed: START:STOP, integers") from None
    return a, b
