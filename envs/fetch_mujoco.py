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
runs when Gymnasium-Robotics is imported, by whoever imports it: by this package when a Fetch task is made
(:func:`robotics_env_class`), or by the user's own ``import gymnasium_robotics`` after ``import sb3_genrl`` (a finder
on ``sys.meta_path``, :func:`fix_on_import`, installed by :mod:`sb3_genrl.envs`, runs it then). ``import sb3_genrl``
alone neither imports Gymnasium-Robotics nor changes it.
"""

from __future__ import annotations

import importlib
import importlib.abc
import sys
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
from gymnasium.envs.registration import load_env_creator, registry

ROBOTICS_HINT = (
    'the Fetch tasks need Gymnasium-Robotics: pip install "sb3-genrl[robotics]" '
    '(or pip install -e ".[robotics]" in a checkout)'
)
# Joint type -> (numbers in qpos, numbers in qvel) of each helper, exactly as Gymnasium-Robotics 1.4.2 counts them
# (its get_joint_qvel counts 4 for a ball joint; kept, the fix changes nothing but the comparison).
_SIZES = {
    "get_joint_qpos": {0: 7, 1: 4},
    "set_joint_qpos": {0: 7, 1: 4},
    "get_joint_qvel": {0: 6, 1: 4},
    "set_joint_qvel": {0: 6, 1: 3},
}
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


def _set_aside(own_ids: tuple[str, ...]) -> dict[str, Any]:
    """Remove from Gymnasium's registry those of ``own_ids`` that this package registered; return them."""
    return {
        env_id: registry.pop(env_id)
        for env_id in own_ids
        if env_id in registry and str(getattr(registry[env_id], "entry_point", "")).startswith("sb3_genrl.")
    }


class _FixOnImport(importlib.abc.MetaPathFinder):
    """Finds ``gymnasium_robotics`` through the other finders and wraps its import: this package's Fetch ids set aside
    while it registers its own (no override warning; ours are put back), its joint helpers fixed right after."""

    def __init__(self, own_ids: tuple[str, ...]) -> None:
        self.own_ids = own_ids

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "gymnasium_robotics":
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                break
        else:
            return None
        if spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        run, own_ids = spec.loader.exec_module, self.own_ids

        def exec_module(module: Any) -> None:
            own = _set_aside(own_ids)
            try:
                run(module)
            finally:
                registry.update(own)
            fix_joint_helpers()

        spec.loader.exec_module = exec_module  # a loader instance of this one spec
        return spec


def fix_on_import(own_ids: tuple[str, ...] = ()) -> None:
    """Fix Gymnasium-Robotics' joint helpers now if it is imported, else as soon as anything imports it (idempotent).

    :param own_ids: this package's ids of the Fetch tasks, kept over the ones Gymnasium-Robotics registers
    """
    if "gymnasium_robotics" in sys.modules:
        fix_joint_helpers()
    elif not any(isinstance(finder, _FixOnImport) for finder in sys.meta_path):
        sys.meta_path.insert(0, _FixOnImport(own_ids))


def import_robotics(own_ids: tuple[str, ...] = ()) -> Any:
    """Import Gymnasium-Robotics (which registers its env ids) and fix its joint helpers; return the module.

    :param own_ids: ids this package registered for the Fetch tasks (their entry points make Gymnasium-Robotics' classes
        after this fix); they are set aside while Gymnasium-Robotics registers its own, without Gymnasium's warning
        about overriding them, and then put back
    """
    own = _set_aside(own_ids) if "gymnasium_robotics" not in sys.modules else {}
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
    import_robotics(own_ids)
    return load_env_creator(entry_point_of(env_id))


def entry_point_of(env_id: str) -> str:
    """Gymnasium-Robotics' entry point of a Fetch id, e.g. ``gymnasium_robotics.envs.fetch.push:MujocoFetchPushEnv``."""
    name = env_id.removeprefix("Fetch").removesuffix("-v4")
    module = {"Reach": "reach", "Push": "push", "Slide": "slide", "PickAndPlace": "pick_and_place"}[name]
    return f"gymnasium_robotics.envs.fetch.{module}:MujocoFetch{name}Env"
