"""The versions of the packages a result depends on, recorded beside it.

MuJoCo's patch releases can change contact-rich simulation (4.0.0 and 4.0.1 play the same FetchSlide strikes and hockey
shots to different ends), so every result records the simulator it ran on, not only sb3-genrl's version.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

PACKAGES = ("sb3-genrl", "mujoco", "gymnasium", "gymnasium-robotics", "stable-baselines3", "torch", "numpy")


def package_versions() -> dict[str, str]:
    """The installed version of each of :data:`PACKAGES` that is installed, keyed by its name with ``_`` for ``-``
    (``{"sb3_genrl": "0.1.0", "mujoco": "4.0.1", ...}``); read from the installed metadata, nothing is imported."""
    found = {}
    for name in PACKAGES:
        try:
            found[name.replace("-", "_")] = version(name)
        except PackageNotFoundError:
            continue
    return found
