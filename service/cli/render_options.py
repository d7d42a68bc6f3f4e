"""The options of the commands that render a scene (``simulate``, ``export mitsuba``), declared
once (typer copies an option for each command that uses it)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from service.cli import ranges
from service.cli.common import number_option

#: ``--spp``: samples per pixel (None: the scene's)
SppOption = Annotated[
    int | None, number_option("--spp", help="Samples per pixel (default: the scene's).",
                              allowed=ranges.SPP)]
#: ``--max-bounces``: surface interactions per path (None: the scene's)
MaxBouncesOption = Annotated[
    int | None, number_option("--max-bounces", help="Surface interactions per path.",
                              allowed=ranges.MAX_BOUNCES)]
#: ``--integrator``: direct or path (None: the scene's)
IntegratorOption = Annotated[
    str | None, typer.Option(help="direct or path (default: the scene's).")]
#: ``--turntable-deg``: the turntable angle instead of the scene's
TurntableDegOption = Annotated[
    float | None, number_option("--turntable-deg", help="Override the turntable angle [deg].",
                                allowed=ranges.TURNTABLE_DEG)]
#: ``--calibration``: a calibration file to apply instead of the scene's own
CalibrationFileOption = Annotated[
    Path | None, typer.Option("--calibration", help="Calibration file to apply "
                              "(docs/calibration.md); replaces the scene's own 'calibration'.")]
