"""OpenCV's chessboard sample photographs (``left01.jpg`` ... ``left14.jpg``), found or fetched.

The public set the photo calibration is checked against (``calibrate intrinsics``,
docs/calibration.md): 13 photographs (no ``left10``) of a chessboard of 10 x 7 squares (9 x 6
inner corners), 640 x 480, 8-bit JPEG, shipped with OpenCV's samples (``samples/data``) and by
Debian's ``opencv-doc`` package (4.6.0) in ``/usr/share/doc/opencv-doc/examples/data/``. Their
published calibration is OpenCV's own test, ``modules/python/test/test_calibration.py`` of
opencv/opencv (:data:`PUBLISHED`). The images are not copied into the repository:
:func:`opencv_samples_dir` finds them (``$TOFTWIN_OPENCV_SAMPLES``, the installed package) or
fetches the package into a cache, and checks every file's MD5.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

#: the variable naming a folder that holds the photographs
SAMPLES_VARIABLE = "TOFTWIN_OPENCV_SAMPLES"
#: where Debian's opencv-doc installs them
DEBIAN_DIR = Path("/usr/share/doc/opencv-doc/examples/data")
#: where :func:`opencv_samples_dir` unpacks them when it has to fetch the package
CACHE_DIR = Path.home() / ".cache" / "toftwin" / "opencv-doc"
#: the package's path of the photographs inside its .deb
DEB_MEMBER = "./usr/share/doc/opencv-doc/examples/data"
#: the photographs and their MD5s (opencv-doc 4.6.0+dfsg-12)
MD5 = {
    "left01.jpg": "4ca26f60869a29faa40a819d1747ab85",
    "left02.jpg": "c0a779a00ecbf27033258a3de376901b",
    "left03.jpg": "3f947848a24656905a15c8a8ecca735c",
    "left04.jpg": "f537c515073cc4d3f5a594740644db30",
    "left05.jpg": "0d39e76dc170823f3bdf0e3b312b4a95",
    "left06.jpg": "0325f4da8cf132821048fef40b7863cd",
    "left07.jpg": "3e23a3c286075d808a7f88467a1738b6",
    "left08.jpg": "03f04bf032c0e81bd1e86edb069b4580",
    "left09.jpg": "c463b6d5d38954d4409f5704f2c20844",
    "left11.jpg": "03e63872fc16b89d97d62f8a5d2a50f0",
    "left12.jpg": "3a9748c781e5749a309e4f5d46854037",
    "left13.jpg": "9295399f6e14460b7bf56975bf657886",
    "left14.jpg": "0804d8c1ed3ca5c0cb12d6b0f274daef",
}
#: the board: squares (squares_x, squares_y) as ``--squares`` counts them
SQUARES = (10, 7)
#: OpenCV's published calibration of the set (flags 0: k1, k2, p1, p2, k3 free) [px]:
#: modules/python/test/test_calibration.py, ``cameraMatrixTest``
PUBLISHED = {"fx_px": 532.80992189, "fy_px": 532.93346422, "cx_px": 342.4952186,
             "cy_px": 233.8879292}

HOW_TO_GET_THEM = (
    "OpenCV's sample photographs left01.jpg ... left14.jpg (no left10) are needed. Either "
    "install Debian's package (`apt-get install opencv-doc`: they land in "
    f"{DEBIAN_DIR}), or let this helper fetch it (needs `apt-get download` and `dpkg-deb`, and "
    f"network access to Debian's archive; it unpacks them into {CACHE_DIR}), or copy them from "
    "OpenCV's source tree (samples/data/left*.jpg of github.com/opencv/opencv, 4.x) into a "
    f"folder and set {SAMPLES_VARIABLE}=that folder."
)


class SamplesUnavailableError(RuntimeError):
    """The photographs are neither present nor fetchable; the message says how to get them."""


def _md5(path: Path) -> str:
    return hashlib.md5(path.read_bytes()).hexdigest()


def check_samples(folder: Path) -> list[str]:
    """What is wrong with ``folder`` as the sample set: missing files, wrong MD5s (empty: fine)."""
    problems = []
    for name, md5 in MD5.items():
        path = folder / name
        if not path.is_file():
            problems.append(f"{path} is missing")
        elif _md5(path) != md5:
            problems.append(f"{path} has MD5 {_md5(path)}, expected {md5}")
    return problems


def _fetch_into(cache: Path) -> None:
    """``apt-get download opencv-doc`` in a temporary folder and unpack the photographs."""
    for tool in ("apt-get", "dpkg-deb", "tar"):
        if shutil.which(tool) is None:
            raise SamplesUnavailableError(f"{tool} is not available. {HOW_TO_GET_THEM}")
    with tempfile.TemporaryDirectory() as tmp:
        run = subprocess.run(["apt-get", "download", "opencv-doc"], cwd=tmp,
                             capture_output=True, text=True, check=False)
        debs = sorted(Path(tmp).glob("opencv-doc_*.deb"))
        if run.returncode != 0 or not debs:
            raise SamplesUnavailableError(
                f"`apt-get download opencv-doc` failed ({run.stderr.strip()[-300:]}). "
                f"{HOW_TO_GET_THEM}")
        members = [f"{DEB_MEMBER}/{name}" for name in MD5]
        unpack = Path(tmp) / "unpacked"
        unpack.mkdir()
        deb = subprocess.Popen(["dpkg-deb", "--fsys-tarfile", str(debs[0])],
                               stdout=subprocess.PIPE)
        tar = subprocess.run(["tar", "-x", "-C", str(unpack), *members], stdin=deb.stdout,
                             capture_output=True, text=True, check=False)
        deb.stdout.close()
        deb.wait()
        if tar.returncode != 0 or deb.returncode != 0:
            raise SamplesUnavailableError(
                f"unpacking {debs[0].name} failed ({tar.stderr.strip()[-300:]}). "
                f"{HOW_TO_GET_THEM}")
        cache.mkdir(parents=True, exist_ok=True)
        for name in MD5:
            shutil.copyfile(unpack / DEB_MEMBER / name, cache / name)


def opencv_samples_dir() -> Path:
    """The folder holding the 13 photographs, their MD5s checked.

    ``$TOFTWIN_OPENCV_SAMPLES`` when set (it must hold them), else Debian's opencv-doc folder
    when it has them, else :data:`CACHE_DIR`, fetched there from Debian's archive when needed.
    Raises :class:`SamplesUnavailableError` saying how to get them when none of that works.
    """
    given = os.environ.get(SAMPLES_VARIABLE, "").strip()
    if given:
        problems = check_samples(Path(given))
        if problems:
            raise SamplesUnavailableError(f"{SAMPLES_VARIABLE}={given}: {problems[0]}. "
                                          f"{HOW_TO_GET_THEM}")
        return Path(given)
    if not check_samples(DEBIAN_DIR):
        return DEBIAN_DIR
    if check_samples(CACHE_DIR):
        _fetch_into(CACHE_DIR)
        problems = check_samples(CACHE_DIR)
        if problems:
            raise SamplesUnavailableError(f"after fetching opencv-doc: {problems[0]}. "
                                          f"{HOW_TO_GET_THEM}")
    return CACHE_DIR


def sample_paths() -> list[Path]:
    """The 13 photographs, in order."""
    folder = opencv_samples_dir()
    return [folder / name for name in MD5]
