"""``toftwin serve``, ``toftwin compare`` and ``toftwin bench campaign``: typer command functions.

``service/cli.py`` registers them (see :func:`register`). ``python -m service.serve_cmd`` runs the
same commands without it.
"""

from __future__ import annotations

import json
import logging
import os
import secrets
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from sim_core.errors import InvalidInputError

console = Console()
err_console = Console(stderr=True)


def serve(
    host: Annotated[str | None, typer.Option(help="Address to bind (default 127.0.0.1).")] = None,
    port: Annotated[int | None, typer.Option(help="TCP port (default 8000).")] = None,
    data_dir: Annotated[
        Path | None,
        typer.Option("--data-dir", help="Frames and database (default ./toftwin-data)."),
    ] = None,
    simulated: Annotated[
        bool, typer.Option("--simulated", help="Run on the device simulators.")
    ] = False,
    executor: Annotated[
        str | None, typer.Option(help="local (process pool), thread, or dask://HOST:PORT.")
    ] = None,
    workers: Annotated[int | None, typer.Option(help="Local executor workers.")] = None,
    settings_file: Annotated[
        Path | None, typer.Option("--settings", help="Settings file (dotenv, TOFTWIN_* keys).")
    ] = None,
    log_level: Annotated[str, typer.Option(help="debug, info, warning, error.")] = "info",
) -> None:
    """Start the REST API (uvicorn); --simulated runs on the simulators and the satellite scene."""
    import uvicorn
    from pydantic import ValidationError

    from service.app import create_app
    from service.config import Settings

    token = None
    if simulated and "TOFTWIN_TOKEN" not in os.environ and settings_file is None:
        token = session_token(data_dir or Path("toftwin-data"))
    try:
        settings = Settings.load(
            settings_file, host=host, port=port, data_dir=data_dir,
            simulated=simulated or None, executor=executor, workers=workers, token=token,
        )
    except ValidationError as exc:
        for e in exc.errors():
            field = ".".join(str(p) for p in e["loc"]) or "settings"
            err_console.print(f"[bold red]error:[/] TOFTWIN_{field.upper()}: {e['msg']}")
        raise typer.Exit(code=2) from None
    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    if settings.host not in ("127.0.0.1", "localhost", "::1"):
        err_console.print(f"[yellow]warning:[/] listening on {settings.host}, not loopback")
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port,
                log_level=log_level.lower())


def session_token(data_dir: Path) -> str:
    """A random bearer token for a simulated service started without one.

    Written to ``DATA_DIR/token`` (mode 0600) and printed once, so that the first command of the
    README works on a fresh machine without a placeholder secret; a real rig needs TOFTWIN_TOKEN.
    """
    data_dir.mkdir(parents=True, exist_ok=True)
    path = data_dir / "token"
    token = secrets.token_urlsafe(24)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as fh:
        fh.write(token + "\n")
    err_console.print(f"simulated rig: no TOFTWIN_TOKEN given, this session's token is in {path}")
    return token


def compare(
    measured_dir: Annotated[Path, typer.Argument(help="Measured frame folder (raw.npz).")],
    simulated_dir: Annotated[Path, typer.Argument(help="Simulated frame folder (frame.npz).")],
    mask: Annotated[
        str, typer.Option(help="turntable, objects, depth_window, region or all.")
    ] = "turntable",
    objects: Annotated[
        str | None, typer.Option(help="Comma-separated object names (--mask objects).")
    ] = None,
    near_m: Annotated[float | None, typer.Option("--near-m", help="Window start [m].")] = None,
    far_m: Annotated[float | None, typer.Option("--far-m", help="Window end [m].")] = None,
    rows: Annotated[str | None, typer.Option(help="Region rows START:STOP.")] = None,
    cols: Annotated[str | None, typer.Option(help="Region cols START:STOP.")] = None,
    out: Annotated[Path, typer.Option("--out", help="JSON file to write.")] = Path(
        "comparison.json"),
) -> None:
    """Table 5 (mean, variance, MSE, SSIM, PSNR of grey and depth) of two frame folders."""
    from pydantic import ValidationError

    from service.comparison import build_mask, load_measured, load_simulated
    from service.comparison import compare as compare_images
    from service.schemas import MaskSpec
    from sim_core.metrics import TABLE_HEADER

    try:
        spec = MaskSpec(kind=mask, names=objects.split(",") if objects else None,
                        near_m=near_m, far_m=far_m, rows=_pair("--rows", rows),
                        cols=_pair("--cols", cols))
        measured = load_measured(measured_dir)
        simulated, arrays, meta = load_simulated(simulated_dir)
        m = build_mask(spec, measured, arrays.get("object_id"), meta.get("object_names", []),
                       meta.get("turntable_object_ids", []))
        report = compare_images(measured, simulated, m)
    except ValidationError as exc:
        err_console.print(f"[bold red]error:[/] --mask: {exc.errors()[0]['msg']}")
        raise typer.Exit(code=2) from None
    except InvalidInputError as exc:
        err_console.print(f"[bold red]error:[/] {exc}")
        raise typer.Exit(code=2) from None
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


def bench_campaign(
    poses: Annotated[int, typer.Option(help="Poses per campaign.")] = 12,
    repeats: Annotated[int, typer.Option(help="Repeats per pose.")] = 1,
    spp: Annotated[int, typer.Option(help="Samples per pixel of the simulations.")] = 16,
    camera_spp: Annotated[int, typer.Option(help="Samples per pixel of the camera twin.")] = 8,
    workers: Annotated[list[int] | None, typer.Option(help="Local worker counts.")] = None,
    dask: Annotated[
        bool, typer.Option("--dask", help="Also on a LocalCluster with 1 and 2 workers.")
    ] = False,
    rounds: Annotated[int, typer.Option(help="Timed campaigns per configuration.")] = 1,
    out: Annotated[Path | None, typer.Option("--out", help="JSON file of the figures.")] = None,
) -> None:
    """Poses per minute of a simulated campaign, and where the time goes per pose."""
    from service.bench_campaign import run_campaign_benchmark

    run_campaign_benchmark(poses, repeats, spp, camera_spp, workers or [1, 2], dask, out,
                           console, rounds)


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    """Add ``serve``, ``compare`` and ``bench campaign`` to the ``toftwin`` app."""
    app.command("serve")(serve)
    app.command("compare")(compare)
    bench_app.command("campaign")(bench_campaign)


def _standalone() -> typer.Typer:
    app = typer.Typer(no_args_is_help=True, add_completion=False)
    bench = typer.Typer(no_args_is_help=True)
    app.add_typer(bench, name="bench")
    register(app, bench)
    return app


if __name__ == "__main__":
    _standalone()()
