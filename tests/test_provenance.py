"""Tests of sb3_genrl.provenance: the package versions a result records."""

import mujoco
import numpy as np
import stable_baselines3
import torch

import sb3_genrl
from sb3_genrl.provenance import package_versions


def test_package_versions_name_the_installed_simulator_and_libraries() -> None:
    found = package_versions()
    assert found["mujoco"] == mujoco.__version__
    assert found["stable_baselines3"] == stable_baselines3.__version__
    assert found["torch"] == torch.__version__ and found["numpy"] == np.__version__
    assert found["sb3_genrl"] == sb3_genrl.__version__
    assert all(isinstance(value, str) and value for value in found.values())
