"""The service's settings: one :class:`Settings`, read from the environment (``TOFTWIN_*``).

Every field can be set as an environment variable with the prefix ``TOFTWIN_`` (``TOFTWIN_TOKEN``,
``TOFTWIN_DATA_DIR``, ...) or in a settings file in dotenv format (``toftwin serve --settings
FILE``); keyword arguments (the CLI options) win over both. Construction fails fast, naming the
field, when the token is missing, a placeholder or too short, or the executor is malformed (or
is ``dask://...`` without Dask's ``distributed``, the ``dask`` extra, installed).
"""

from __future__ import annotations

import importlib.util
import os
import re
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from drivers.errors import DeviceInputError
from drivers.sim.faults import parse_rig_fault
from sim_core.adaptive import NOISE_FRACTION_RANGE
from sim_core.errors import InvalidInputError
from sim_core.scene_spec import EXAMPLES_DIR
from sim_core.twin_file import load_reality

#: tokens that are documentation placeholders, never real secrets
PLACEHOLDER_TOKENS = frozenset(
    {"changethis", "change-me", "changeme", "secret", "token", "password", "toftwin"}
)
MIN_TOKEN_LENGTH = 12

_DASK = re.compile(r"^dask://(?P<host>[A-Za-z0-9_.:\[\]-]+):(?P<port>\d{1,5})$")

#: what a Dask executor needs and is not installed by default (the project's ``dask`` extra)
DASK_MISSING = ("Dask's `distributed` is not installed; a dask:// executor needs the project's "
                "dask extra: pip install -e '.[dask]'")


def dask_scheduler(executor: str) -> str | None:
    """``tcp://HOST:PORT`` of a ``dask://HOST:PORT`` executor value, else None.

    >>> dask_scheduler("dask://10.0.0.5:8786"), dask_scheduler("local")
    ('tcp://10.0.0.5:8786', None)
    """
    m = _DASK.match(executor)
    return None if m is None else f"tcp://{m['host']}:{m['port']}"


def dask_installed() -> bool:
    """Whether Dask's ``distributed`` can be imported (the ``dask`` extra is installed)."""
    try:
        return importlib.util.find_spec("distributed") is not None
    except (ImportError, ValueError):  # a broken or half-removed installation
        return False


class Settings(BaseSettings):
    """Everything the service is configured with.

    Attributes
    ----------
    token : SecretStr
        Bearer token required by every call that moves hardware or changes data.
    host, port : str, int
        Where ``toftwin serve`` listens (loopback unless told otherwise).
    data_dir : Path
        Frames (``frames/<id>/``) and, by default, the SQLite database.
    database_url : str or None
        SQLAlchemy URL; ``sqlite:///<data_dir>/toftwin.db`` when None.
    simulated : bool
        Run on the device simulators with a rendered camera instead of real hardware.
    executor : str
        ``local`` (process pool, the default), ``thread`` (in-process threads, for tests and
        debugging) or ``dask://HOST:PORT`` (an existing Dask scheduler).
    workers : int
        Processes (or threads) of a local executor.
    sim_motion : {"instant", "real"}
        The simulated turntable: ``instant`` (moves finish at once, the default) or ``real``
        (it moves at its speed, 20 deg/s, so a move can be watched and stopped). Only with
        ``simulated``.
    reality : Path or None
        The simulated lab's reality file (:mod:`sim_core.twin_file`): how its world differs from
        the nominal scene. None: the default reality (:func:`drivers.sim.world.default_reality`).
        Only with ``simulated``; never visible through the API.
    pipeline_depth : int or None
        Poses of a campaign in flight at once (rig stage of the next pose overlapping the
        simulation of the previous ones); None: as many as the executor has workers. 1 makes
        campaigns strictly sequential.
    """

    model_config = SettingsConfigDict(env_prefix="TOFTWIN_", extra="ignore", env_file=None)

    token: SecretStr = Field(description="Bearer token for calls that move or change things.")
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    data_dir: Path = Path("toftwin-data")
    database_url: str | None = None

    simulated: bool = False
    scene: str = Field("satellite_ground_test", pattern=r"^[A-Za-z0-9_-]{1,64}$")
    examples_dir: Path = EXAMPLES_DIR

    executor: str = "local"
    workers: int = Field(1, ge=1, le=64)
    pipeline_depth: int | None = Field(None, ge=1, le=64)
    sim_threads: int | None = Field(None, ge=1, le=256)
    sim_spp: int = Field(16, ge=1, le=65536)
    max_spp: int = Field(256, ge=1, le=65536)
    job_timeout_s: float = Field(600.0, gt=0.0)

    camera_spp: int = Field(8, ge=1, le=4096)
    #: the simulated camera renders its world with at least ``camera_spp`` samples and more
    #: where the Monte Carlo error is above this fraction of its sensor's noise (the lab's
    #: "reality" then has little render noise frozen into it, as a real scene has none);
    #: None: ``camera_spp`` everywhere
    camera_noise_fraction: float | None = Field(None, ge=NOISE_FRACTION_RANGE[0],
                                                le=NOISE_FRACTION_RANGE[1])
    camera_integrator: Literal["direct", "path"] = "path"
    camera_seed: int = Field(0, ge=0, le=2**31 - 1)

    turntable_port: str | None = None
    turntable_address: int = Field(1, ge=1, le=31)
    lamp_port: str | None = None
    shutter_port: str | None = None
    camera_serial: str | None = None
    #: how the camera is reached: ``usb`` (our wire format over pyusb; the simulated rig's USB
    #: camera), ``royale`` (PMD's roypy in this process) or ``tcp://HOST:PORT`` (a camera bridge:
    #: ``toftwin_camera_bridge`` beside a real camera, ``toftwin camera-bridge --simulated``
    #: filming the simulated rig's world)
    camera: str = "usb"
    #: what the camera streams: ``raw`` (royale's raw phase frames, reconstructed by us) or
    #: ``depth`` (royale's processed depth and grey, ``IDepthDataListener``: for a camera
    #: without raw access; camera ``royale`` or a bridge; comparisons say so)
    camera_mode: Literal["raw", "depth"] = "raw"
    #: a campaign paused because its camera (or camera bridge) went away watches this long for
    #: it to deliver frames again and then resumes by itself (:mod:`service.lab.camera_return`);
    #: 0: the operator resumes, as after any other device fault [s]
    camera_return_s: float = Field(900.0, ge=0.0, le=86400.0)
    #: how often that watch tries a capture [s]
    camera_return_poll_s: float = Field(2.0, gt=0.0, le=60.0)
    solar_stable_timeout_s: float = Field(60.0, gt=0.0)
    rig_wait_s: float = Field(30.0, gt=0.0)

    max_body_bytes: int = Field(1_000_000, ge=1024)
    max_scene_objects: int = Field(256, ge=1, le=10000)
    max_scene_pixels: int = Field(1_000_000, ge=1)
    max_scene_triangles: int = Field(2_000_000, ge=1)
    max_poses: int = Field(720, ge=1, le=100000)
    max_repeats: int = Field(100, ge=1, le=10000)
    sse_interval_s: float = Field(0.5, gt=0.0)
    sse_max_s: float = Field(3600.0, gt=0.0)
    sse_max_streams: int = Field(100, ge=1, le=10000)
    faults: list[str] = Field(default_factory=list)
    sim_motion: Literal["instant", "real"] = "instant"
    reality: Path | None = None
    min_free_bytes: int = Field(1_000_000_000, ge=0)

    @model_validator(mode="after")
    def _faults_need_simulators(self) -> Settings:
        if self.faults and not self.simulated:
            raise ValueError("faults: arming device faults needs the simulated rig "
                             "(TOFTWIN_SIMULATED=true, serve --simulated)")
        if self.sim_motion != "instant" and not self.simulated:
            raise ValueError("sim_motion: the simulated turntable's motion needs the simulated "
                             "rig (TOFTWIN_SIMULATED=true, serve --simulated)")
        if self.camera == "royale" and self.simulated:
            raise ValueError("camera: royale opens a real pico flexx; the simulated rig's camera "
                             "is usb or a simulated camera bridge (tcp://HOST:PORT)")
        if self.camera_mode == "depth" and self.camera == "usb":
            raise ValueError("camera_mode: royale's processed depth comes from camera royale or "
                             "a camera bridge (tcp://HOST:PORT); our USB wire format is raw only")
        if self.reality is not None and not self.simulated:
            raise ValueError("reality: a reality file describes the simulated lab's world; it "
                             "needs the simulated rig (TOFTWIN_SIMULATED=true, serve --simulated)")
        return self

    @field_validator("camera")
    @classmethod
    def _known_camera(cls, v: str) -> str:
        if v in ("usb", "royale"):
            return v
        from drivers.camera.bridge_client import parse_bridge_url
        from drivers.errors import DeviceInputError

        try:
            parse_bridge_url(v)
        except DeviceInputError:
            raise ValueError(f"got {v!r}; allowed: 'usb', 'royale' or a camera bridge "
                             "'tcp://HOST:PORT' (PORT 1..65535)") from None
        return v

    @field_validator("reality")
    @classmethod
    def _valid_reality(cls, v: Path | None) -> Path | None:
        if v is not None:
            try:
                load_reality(v)
            except InvalidInputError as exc:
                raise ValueError(str(exc)) from None
        return v

    @field_validator("faults")
    @classmethod
    def _known_faults(cls, v: list[str]) -> list[str]:
        for i, text in enumerate(v):
            try:
                parse_rig_fault(text)
            except DeviceInputError as exc:
                raise ValueError(f"[{i}] {exc.message}") from None
        return v
    stop_wait_s: float = Field(30.0, ge=0.0)

    @field_validator("token")
    @classmethod
    def _real_token(cls, v: SecretStr) -> SecretStr:
        text = v.get_secret_value()
        if text.strip().lower() in PLACEHOLDER_TOKENS:
            raise ValueError("is a placeholder; set TOFTWIN_TOKEN to a random secret")
        if len(text) < MIN_TOKEN_LENGTH:
            raise ValueError(
                f"has {len(text)} characters; at least {MIN_TOKEN_LENGTH} are required "
                "(e.g. `python -c 'import secrets; print(secrets.token_urlsafe(24))'`)"
            )
        return v

    @field_validator("executor")
    @classmethod
    def _known_executor(cls, v: str) -> str:
        if v in ("local", "thread"):
            return v
        if _DASK.match(v):
            if not dask_installed():
                raise ValueError(f"got {v!r}: {DASK_MISSING}")
            return v
        raise ValueError(f"got {v!r}; allowed: 'local', 'thread' or 'dask://HOST:PORT'")

    @property
    def database(self) -> str:
        """The SQLAlchemy URL in use."""
        return self.database_url or f"sqlite:///{self.data_dir / 'toftwin.db'}"

    @property
    def dask_address(self) -> str | None:
        """``tcp://HOST:PORT`` of the Dask scheduler, or None for a local executor."""
        return dask_scheduler(self.executor)

    @property
    def depth(self) -> int:
        """Poses in flight during a campaign."""
        return self.pipeline_depth or self.workers

    @property
    def threads_per_job(self) -> int:
        """Embree/numba threads of one simulation job (cores shared among local workers)."""
        if self.sim_threads is not None:
            return self.sim_threads
        return max(1, (os.cpu_count() or 1) // self.workers)

    @classmethod
    def load(cls, settings_file: str | Path | None = None, **overrides: Any) -> Settings:
        """Settings from the environment, an optional dotenv file, and explicit overrides."""
        given = {k: v for k, v in overrides.items() if v is not None}
        if settings_file is not None:
            return cls(_env_file=str(settings_file), **given)  # type: ignore[call-arg]
        return cls(**given)
