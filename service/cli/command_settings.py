"""The :class:`~service.settings.Settings` of a command, and the rig the commands drive.

``toftwin serve`` and every command that drives the rig (``calibrate rig``, ``calibrate
material``, ``fit-object``) read their settings the same way (:func:`load_settings`): from the
environment (``TOFTWIN_*``) and an optional settings file, the command's options winning, every
invalid value an exit with code 2 naming the option (or the variable). The rig commands then
get their rig from the service's own builder (:func:`open_command_rig`, which calls
:func:`service.lab.rig_builder.open_rig`), so that the same environment gives the command line
and the service the same rig: the same ports, turntable address and camera serial for the real
one; the same faults, motion and reality for the simulated lab. The options they declare alike
(``--reality``, ``--camera-spp``, ...) are declared here once.
"""

from __future__ import annotations

import contextlib
import secrets
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from service.cli import ranges
from service.cli.common import number_option, print_error

if TYPE_CHECKING:
    from drivers.rig import Rig
    from drivers.sim.world import SimulatedWorld
    from service.lab.scenes import SceneSource
    from service.settings import Settings

#: the settings the options of a rig command set: field -> option
RIG_OPTION_OF_FIELD = {"simulated": "--simulated", "reality": "--reality",
                       "camera_spp": "--camera-spp", "camera_seed": "--seed"}

# -- the options of the rig commands (typer copies an option for each command that uses it) ----
#: ``--out``: the folder a rig command writes (``calibrate rig``, ``fit-object``)
OutFolderOption = Annotated[Path, typer.Option("--out", help="Output folder (must not exist).")]
#: ``--reality``: the simulated lab's hidden truth
RealityOption = Annotated[
    Path | None,
    typer.Option("--reality", help="The simulated lab's reality file (needs --simulated)."),
]
#: ``--camera-spp``: how finely the simulated camera renders
CameraSppOption = Annotated[
    int, number_option("--camera-spp", help="Samples per pixel of the simulated camera.",
                       allowed=ranges.CAMERA_SPP)
]
#: ``--seed``: the simulated camera's noise (``calibrate material`` says what else it seeds)
CameraSeedOption = Annotated[
    int, number_option("--seed", help="Noise seed of the simulated camera.",
                       allowed=ranges.CAMERA_SEED)
]


def load_settings(settings_file: Path | None, option_of_field: Mapping[str, str],
                  **given: Any) -> Settings:
    """Settings from the environment and ``settings_file``, the options ``given`` winning (None:
    not given); an invalid value exits with code 2, naming its option (``option_of_field``)
    where an option set it, else its ``TOFTWIN_*`` variable."""
    from pydantic import ValidationError

    from service.settings import Settings

    try:
        return Settings.load(settings_file, **given)
    except ValidationError as exc:
        for e in exc.errors():
            field = ".".join(str(p) for p in e["loc"]) or "settings"
            name = f"TOFTWIN_{field.upper()}"
            top = str(e["loc"][0]) if e["loc"] else ""
            if given.get(top) is not None and top in option_of_field:
                name = f"{option_of_field[top]}{field[len(top):]} ({name})"
            print_error(f"{name}: {e['msg']}")
        raise typer.Exit(code=2) from None


def rig_settings(*, simulated: bool, reality: Path | None, camera_spp: int,
                 camera_integrator: str, camera_seed: int) -> Settings:
    """The settings of a command that drives the rig: the environment's, as ``toftwin serve``
    reads them, with the command's options.

    The real rig's ports, turntable address and camera serial come from the environment
    (``TOFTWIN_TURNTABLE_PORT``, ``TOFTWIN_TURNTABLE_ADDRESS``, ...), as do the simulated
    lab's faults and turntable motion; the simulated camera renders with the command's
    ``--camera-spp``, ``--seed`` and integrator. A command serves nothing: its token is a
    throwaway one (``TOFTWIN_TOKEN`` is neither needed nor read).
    """
    return load_settings(None, RIG_OPTION_OF_FIELD, token=secrets.token_urlsafe(24),
                         simulated=simulated or None, reality=reality, camera_spp=camera_spp,
                         camera_integrator=camera_integrator, camera_seed=camera_seed)


@contextlib.contextmanager
def open_command_rig(settings: Settings,
                     scene: SceneSource) -> Iterator[tuple[Rig, SimulatedWorld | None]]:
    """The rig of ``settings`` (:func:`service.lab.rig_builder.open_rig`) and the simulated
    lab's world (None for the real rig), the rig closed when the block is left.

    A real rig without its ports exits with code 2 naming the missing ``TOFTWIN_*`` variables;
    a device that cannot be opened exits with code 1 naming it.
    """
    from drivers.errors import DeviceError
    from service.errors import UnavailableError
    from service.lab.rig_builder import open_rig

    try:
        rig, world = open_rig(settings, scene)
    except UnavailableError as exc:
        print_error(exc.detail)
        raise typer.Exit(code=2) from None
    except (DeviceError, OSError) as exc:
        print_error(f"the rig cannot be opened: {type(exc).__name__}: {exc}")
        raise typer.Exit(code=1) from None
    with rig:
        yield rig, world
