"""Gymnasium-Robotics' Fetch envs on this package's MuJoCo: the import of the optional extra and one compatibility fix.

The Fetch tasks are Gymnasium-Robotics' own envs, unmodified (``pip install -e ".[robotics]"`` installs
``gymnasium-robotics==1.4.2``). Under MuJoCo 4.0 every one of them fails in ``reset`` with a bare
``AssertionError`` in ``gymnasium_robotics/utils/mujoco_utils.py``: its joint helpers (``get_joint_qpos``,
``set_joint_qpos``, ``get_joint_qvel``, ``set_joint_qvel``) test ``joint_type in (mujoco.mjtJoint.mjJNT_HINGE,
mujoco.mjtJoint.mjJNT_SLIDE)``, where ``joint_type`` is a ``numpy.int32`` read from ``model.jnt_type``. MuJoCo 4.0's
enums compare equal to such an integer (``joint_type == mjJNT_HINGE`` is True) but the tuple's own comparison,
``mjJNT_HINGE == joint_type``, is False, so the membership test fails for every hinge and slide joint.

:func:`fix_joint_helpers` replaces those four helpers with the same functions comparing the joint type as an integer,
and only when the upstream test fails under the MuJoCo in use (on a MuJoCo where it works, nothing is replaced). It
runs when a Fetch task is made through this package (:func:`robotics_env_class`), never on ``import sb3_genrl``.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np

ROBOTICS_HINT = ('the Fetch tasks need Gymnasium-Robotics: pip install "sb3-genrl[robotics]" '
                 '(or pip install -e ".[robotics]" in a checkout)')
# Joint type -> (numbers in qpos, numbers in qvel) of each helper, exactly as Gymnasium-Robotics 1.4.2 counts them
# (its get_joint_qvel counts 4 for a ball joint; kept, the fix changes nothing but the comparison).
_SIZES = {"get_joint_qpos": {0: 7, 1: 4}, "set_joint_qpos": {0: 7, 1: 4},
          "get_joint_qvel": {0: 6, 1: 4}, "set_joint_qvel": {0: 6, 1: 3}}
_ONE_NUMBER = (int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE))
assert int(mujoco.mjtJoint.mjJNT_FREE) == 0 and int(mujoco.mjtJoint.mjJNT_BALL) == 1


def upstream_test_fails() -> bool:
    """Whether Gymnasium-Robotics' membership test rejects a hinge joint's type under the MuJoCo in use."""
    joint_type = np.array([mujoco.mjtJoint.mjJNT_HINGE], dtype=np.int32)[0]  # as model.jnt_type[i] gives it
    return joint_type not in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE)


def _joint_helper(name: str) -> Callable[..., Any]:
    """Gymnasium-Robotics' helper ``name`` with the joint type compared as an integer."""
    sizes, array = _SIZES[name], "qpos" if name.endswith("qpos") else "qvel"
    address = "jnt_qposadr" if array == "qpos" else "jnt_dofadr"

    def helper(model: mujoco.MjModel, data: mujoco.MjData, joint: str, *value: Any) -> Any:
        joint_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        assert joint_id != -1, f"Joint with name '{joint}' is not part of the model!"
        joint_type = int(model.jnt_type[joint_id])
        assert joint_type in sizes or joint_type in _ONE_NUMBER, f"unknown joint type {joint_type} of {joint!r}"
        start = int(getattr(model, address)[joint_id])
        end = start + sizes.get(joint_type, 1)
        if not value:  # get_joint_*
            return getattr(data, array)[start:end].copy()
        new = np.array(value[0])
        if end - start > 1:
            assert new.shape == (end - start,), f"Value has incorrect shape {joint}: {new}"
        getattr(data, array)[start:end] = new
        return None

    helper.integer_joint_types = True  # type: ignore[attr-defined]
    helper.__name__ = helper.__qualname__ = name
    helper.__doc__ = f"Gymnasium-Robotics' ``{name}``, the joint type compared as an integer (MuJoCo 4.0's enums)."
    return helper


def fix_joint_helpers() -> bool:
    """Replace Gymnasium-Robotics' four joint helpers by integer-comparing ones when their test fails here (see the
    module docstring); idempotent. Returns whether the helpers are (now) the fixed ones."""
    from gymnasium_robotics.utils import mujoco_utils

    if not upstream_test_fails():
        return False
    for name in _SIZES:
        if not getattr(getattr(mujoco_utils, name), "integer_joint_types", False):
            setattr(mujoco_utils, name, _joint_helper(name))
    return True


def import_robotics(own_ids: tuple[str, ...] = ()) -> Any:
    """Import Gymnasium-Robotics (which registers its env ids) and fix its joint helpers; return the module.

    :param own_ids: ids this package registered for the Fetch tasks (their entry points make Gymnasium-Robotics' classes
        after this fix); they are set aside while Gymnasium-Robotics registers its own, without Gymnasium's warning
        about overriding them, and then put back
    """
    from gymnasium.envs.registration import registry

    own = {}
    if "gymnasium_robotics" not in sys.modules:
        own = {env_id: registry.pop(env_id) for env_id in own_ids if env_id in registry
               and str(getattr(registry[env_id], "entry_point", "")).startswith("sb3_genrl.")}
    try:
        module = importlib.import_module("gymnasium_robotics")
    except ImportError as error:
        raise ImportError(f"{ROBOTICS_HINT} ({error})") from error
    finally:
        registry.update(own)
    fix_joint_helpers()
    return module


def robotics_env_class(env_id: str, own_ids: tuple[str, ...] = ()) -> type:
    """Gymnasium-Robotics' env class of ``env_id`` (e.g. ``FetchPush-v4``), its joint helpers fixed."""
    from gymnasium.envs.registration import load_env_creator

    import_robotics(own_ids)
    return load_env_creator(entry_point_of(env_id))


def entry_point_of(env_id: str) -> str:
    """Gymnasium-Robotics' entry point of a Fetch id, e.g. ``gymnasium_robotics.envs.fetch.push:MujocoFetchPushEnv``."""
    name = env_id.removeprefix("Fetch").removesuffix("-v4")
    module = {"Reach": "reach", "Push": "push", "Slide": "slide", "PickAndPlace": "pick_and_place"}[name]
    return f"gymnasium_robotics.envs.fetch.{module}:MujocoFetch{name}Env"
