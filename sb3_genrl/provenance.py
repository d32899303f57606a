"""The versions of the packages a result depends on, recorded beside it.

MuJoCo's patch releases can change contact-rich simulation (4.0.0 and 4.0.1 play the same FetchSlide strikes and hockey
shots to different ends), so every result records the simulator it ran on, not only sb3-genrl's version.
"""

from __future__ import annotations

import pathlib
import subprocess
from importlib.metadata import PackageNotFoundError, version

PACKAGES = ("sb3-genrl", "mujoco", "gymnasium", "gymnasium-robotics", "stable-baselines3", "torch", "numpy")


def package_versions() -> dict[str, str]:
    """The installed version of each of :data:`PACKAGES` that is installed, keyed by its name with ``_`` for ``-``
    (``{"sb3_genrl": "0.2.0", "mujoco": "4.0.1", ...}``); read from the installed metadata, nothing is imported."""
    found = {}
    for name in PACKAGES:
        try:
            found[name.replace("-", "_")] = version(name)
        except PackageNotFoundError:
            continue
    return found


def git_commit(folder: str | pathlib.Path | None = None) -> str | None:
    """The commit checked out in the git work tree holding ``folder`` (default: this package's source), with
    ``+dirty`` appended when tracked files differ from it; ``None`` outside a work tree or without git."""
    where = pathlib.Path(folder) if folder is not None else pathlib.Path(__file__).resolve().parent
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, check=True
        ).stdout.strip()
        changed = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"], cwd=where, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return commit + ("+dirty" if changed else "") if commit else None


def provenance() -> dict[str, str | None]:
    """What a result JSON records about the code that made it: :func:`package_versions` and ``git_commit``."""
    return package_versions() | {"git_commit": git_commit()}
