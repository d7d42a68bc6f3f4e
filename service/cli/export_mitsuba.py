"""``toftwin export mitsuba SCENE --out DIR``: a scene as a Mitsuba 3 scene (issue 29).

``DIR/scene.xml`` and its meshes ``DIR/meshes/*.ply`` (:mod:`sim_core.mitsuba_scene`, the
converter ``toftwin bench mitsuba`` renders with too): Mitsuba's ``mi.load_file`` and
``mi.render`` then give the DC image of the camera's own light that our renderer gives
(docs/export-mitsuba.md). The folder is written beside ``DIR`` and renamed into place when
whole; an existing non-empty ``DIR`` is refused unless ``--force``, which replaces an earlier
export only (a folder holding nothing but ``scene.xml`` and ``meshes/*.ply``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Annotated

import typer

from service.cli import ranges
from service.cli.common import choice, console, fail_invalid, number_option
from service.cli.render_options import CalibrationFileOption, SppOption, TurntableDegOption
from sim_core.errors import InvalidInputError


def export_mitsuba(
    scene: Annotated[Path, typer.Argument(help="Scene file (YAML or JSON): Lambertian "
                                               "materials, an isotropic light, no ambient "
                                               "light, square pixels without distortion.")],
    out: Annotated[Path, typer.Option("--out", help="Folder to write scene.xml and meshes/ "
                                                    "into; a new or empty one, or an earlier "
                                                    "export with --force.")],
    spp: SppOption = None,
    max_bounces: Annotated[
        int | None, number_option("--max-bounces", help="Surface interactions per path of the "
                                  "path integrator (default: the scene's).",
                                  allowed=ranges.MAX_BOUNCES)
    ] = None,
    integrator: Annotated[
        str | None, typer.Option(help="direct (max_depth 2) or path (default: the scene's).")
    ] = None,
    turntable_deg: TurntableDegOption = None,
    solar_suns: Annotated[
        float | None, number_option("--solar-suns", help="Override the solar simulator level "
                                    "[sun]: the export carries no ambient light, so a scene "
                                    "with a solar simulator needs 0 (its shutter closed).",
                                    allowed=ranges.SOLAR_SUNS_OR_OFF)
    ] = None,
    calibration: CalibrationFileOption = None,
    force: Annotated[bool, typer.Option("--force", help="Replace an earlier export in "
                                                        "--out.")] = False,
) -> None:
    """Write SCENE as a Mitsuba 3 scene: --out/scene.xml and its meshes as PLY files."""
    from sim_core.mitsuba_scene import describe_scene
    from sim_core.scene import build_scene
    from sim_core.scene_spec import load_scene_spec
    from sim_core.twin_file import load_calibration

    try:
        _check_out(out, force)
        spec = load_scene_spec(scene)
        twin = None if calibration is None else load_calibration(calibration)
        built = build_scene(spec, base_dir=scene.parent, turntable_deg=turntable_deg,
                            solar_suns=solar_suns, twin=twin)
        render = spec.render
        kind = render.integrator if integrator is None else choice(
            "--integrator", integrator, ("direct", "path"))
        bounces = max_bounces if max_bounces is not None else render.max_bounces
        desc = describe_scene(built, spp=spp if spp is not None else render.spp,
                              bounces=1 if kind == "direct" else bounces,
                              rr_from_bounce=render.russian_roulette_from_bounce)
        xml_path = _write(desc, out)
    except InvalidInputError as exc:
        fail_invalid(exc)
        return
    console.print(f"Mitsuba scene written to {xml_path} ({len(desc.meshes)} meshes, "
                  f"{desc.n_triangles} triangles, {desc.sensor.spp} spp, max_depth "
                  f"{desc.integrator.max_depth}); render it with mi.load_file and mi.render "
                  "(docs/export-mitsuba.md)")


def _foreign_entry(folder: Path) -> str | None:
    """The first entry of ``folder`` an export does not write (``scene.xml``, ``meshes/*.ply``),
    or None if it holds an earlier export only."""
    from sim_core.mitsuba_scene import MESH_FOLDER, SCENE_FILE

    for entry in sorted(folder.iterdir()):
        if entry.name == SCENE_FILE and entry.is_file():
            continue
        if entry.name == MESH_FOLDER and entry.is_dir() and not entry.is_symlink():
            other = next((p for p in sorted(entry.iterdir())
                          if p.suffix != ".ply" or not p.is_file()), None)
            if other is None:
                continue
            return f"{MESH_FOLDER}/{other.name}"
        return entry.name
    return None


def _check_out(out: Path, force: bool) -> None:
    """Refuse an ``--out`` that is a file, lies in a "folder" that is a file, or is a folder
    that is not empty (without ``--force``) or holds more than an earlier export."""
    if out.exists() and not out.is_dir():
        raise InvalidInputError("--out", f"'{out}' is a file; give a folder")
    parent = next((p for p in out.absolute().parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise InvalidInputError("--out", f"'{parent}' is a file, not a folder")
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not force:
        raise InvalidInputError("--out", f"'{out}' is a folder that is not empty; give a new "
                                "or empty one, or --force to replace an earlier export in it")
    foreign = _foreign_entry(out)
    if foreign is not None:
        raise InvalidInputError("--out", f"'{out}' holds '{foreign}', which an export does not "
                                "write: --force replaces an earlier export only (scene.xml, "
                                "meshes/*.ply); give a new or empty folder")


def _write(desc, out: Path) -> Path:
    """Write the export into a temporary folder beside ``out`` and rename it into place; an
    empty or earlier ``out`` is set aside first and removed only once the new one is in its
    place (put back if that fails). Returns the XML's path."""
    from sim_core.files import current_umask, fsync_dir
    from sim_core.mitsuba_scene import SCENE_FILE, write_scene_xml

    parent = out.absolute().parent
    tmp = old = None
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=parent))
        os.chmod(tmp, 0o777 & ~current_umask())  # mkdtemp's is 0700; a folder as any other
        write_scene_xml(desc, tmp)
        if out.exists():
            old = tmp.with_suffix(".old")
            os.rename(out, old)
        os.rename(tmp, out)
        tmp = None
        fsync_dir(parent)
    except OSError as exc:
        if old is not None and not out.exists():
            with contextlib.suppress(OSError):
                os.rename(old, out)
                old = None
        raise InvalidInputError("--out", f"'{out}' could not be written: "
                                f"{exc.strerror or exc}") from None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and out.exists():  # else the earlier export is all there is
            shutil.rmtree(old, ignore_errors=True)
    return out / SCENE_FILE
