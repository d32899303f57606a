"""Tests of sb3_genrl.provenance: the package versions a result records."""

import mujoco
import numpy as np
import stable_baselines3
import torch

import sb3_genrl
from sb3_genrl.provenance import git_commit, package_versions, provenance


def test_package_versions_name_the_installed_simulator_and_libraries() -> None:
    found = package_versions()
    assert found["mujoco"] == mujoco.__version__
    assert found["stable_baselines3"] == stable_baselines3.__version__
    assert found["torch"] == torch.__version__ and found["numpy"] == np.__version__
    assert found["sb3_genrl"] == sb3_genrl.__version__
    assert all(isinstance(value, str) and value for value in found.values())


def test_a_result_records_the_commit_of_its_code(tmp_path) -> None:
    import subprocess

    recorded = provenance()
    assert recorded["sb3_genrl"] == sb3_genrl.__version__
    head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    assert recorded["git_commit"] is not None and recorded["git_commit"].split("+")[0] == head
    assert git_commit(tmp_path) is None  # outside a work tree
