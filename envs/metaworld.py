"""Meta-World's 50 v3 manipulation tasks (Farama's ``metaworld`` 3.1.1) on this package's MuJoCo, with seeded resets.

Meta-World is an optional extra that is installed without its dependencies: ``metaworld`` 3.1.1 pins
``mujoco==3.3.0``, and a plain ``pip install metaworld`` would replace this package's ``mujoco==4.0.1`` and leave
``import mujoco`` broken (``OSError: libmujoco.so.4.0.1``). Install it with
``pip install --no-deps metaworld==3.1.1`` (its other requirements, Gymnasium, NumPy, SciPy and imageio, are this
package's too). ``import sb3_genrl`` registers the ids below when ``metaworld`` can be imported, without importing it.

Two things are fixed, in a subclass of each Meta-World env (Meta-World's own classes are left unchanged):

- **The wider equality rows of newer MuJoCo.** Every Meta-World env fails while it is made with ``ValueError: could not
  broadcast input array from shape (11,) into shape (12,)`` at ``metaworld/sawyer_xyz_env.py:138``: its
  ``reset_mocap_welds`` writes the 11 numbers of a weld (anchor, relative pose, torque scale) into a row of
  ``model.eq_data``, and the MuJoCo in use has 12 numbers a row (``mujoco.mjNEQDATA``; 11 in the MuJoCo 3.3.0 that
  metaworld pins). The subclass writes the same 11 numbers and a 0 after them, which is what MuJoCo itself compiles for
  a weld whose relative pose is given.
- **Seeded resets.** Meta-World's ``reset`` ignores ``seed`` and, in its benchmark classes (``MT1``, ``ML1``), draws
  each task from a fixed list of 50. Here every reset draws the object and goal positions from the env's own random
  generator (``seeded_rand_vec``, ``_freeze_rand_vec`` off), which ``reset(seed=s)`` reseeds, so that one seed gives
  one task, every time, and an action sequence replayed from it gives the same episode.

The goal is observed (the last 3 numbers of the 39-D observation, as in Meta-World's multi-task benchmarks), and an
episode ends at its first success (terminated) or after 500 steps (Meta-World's ``max_path_length``, truncated).
Ending at the first success is Meta-World's own evaluation protocol (``metaworld.evaluation`` turns its
``AutoTerminateOnSuccessWrapper`` on): an episode counts as solved when its task is solved at some step.
The step that ends an episode at its success earns Meta-World's top reward, 10 (``SOLVED_REWARD``), so that an
episode's last reward ranks a solved episode above an unsolved one. ``info["is_success"]`` says whether it has been
solved at some step of the episode so far (``info["success"]``,
Meta-World's own, whether it is solved at this step), so the success read at an episode's last step is Meta-World's.
Several scripted experts solve their task only for a while (on 100 seeded resets, handle-press-v3's expert solves it
within 58 steps on all of them, but at any one step on at most 0.35), so a success read at a fixed last step of an
episode that runs on would miss what Meta-World counts. ``terminate_on_success=False`` gives Meta-World's training env
instead, which runs on after a success (Meta-World's note: an end at success makes the training of step-based learners
unstable); ``info["is_success"]`` still says whether the task has been solved so far.
"""

from __future__ import annotations

import functools
import importlib.util
import inspect
import warnings
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.envs.registration import register, registry

METAWORLD_VERSION = "3.1.1"  # the release the fixes below are written for
INSTALL_HINT = f"Meta-World is an optional extra: pip install --no-deps metaworld=={METAWORLD_VERSION}"
MAX_EPISODE_STEPS = 500  # Meta-World's max_path_length of every task
# The generator preset genrl quickstart trains for a Meta-World task (Task.generator_preset): the Fetch tasks'
# recipe (10 latent dimensions, beta = 0.001, the hand's path weighed in the loss: a Meta-World action moves the hand as
# a Fetch action moves the gripper), chosen by how often its reconstructions of tuning demonstrations, replayed open
# loop, still succeed (docs/guide/your_task.md).
GENERATOR_PRESET = "VAE-FETCH"
# The env a Meta-World task's demonstrations are recorded in (Task.recording_kwargs): its training env, which
# runs on after a success, so that a demonstration keeps the expert's actions after its success up to the horizon.
# Recorded in the env that ends at the first success, a demonstration's actions stop there (hold actions after it),
# and a decoded trajectory that arrives a little late stops short: peg-insert-side-v3's generator reproduced 0.385 of
# such demonstrations against 0.735 of the whole ones (the MT10 benchmark's sizes; docs/guide/your_task.md).
RECORDING_KWARGS = {"terminate_on_success": False}
# The reward of the step that ends an episode at its first success, with Meta-World's v2 rewards (their maximum, which
# most tasks give once the object is within a few cm of its goal). Meta-World's own reward of that step does not tell a
# success from a near miss: pick-place-v3 gives 10 only within 5 cm of the goal while its success is within 7 cm, so a
# first success earns about 6.75 (the median in the MT10 benchmark's GenRL runs), and 1 in 10 of their failed episodes
# ends at 6.66 or more; window-open-v3's first successes earn 3.6 to 8.3.
SOLVED_REWARD = 10.0
# Meta-World's 50 v3 tasks (metaworld.env_dict.ALL_V3_ENVIRONMENTS, in its order; a test checks this copy)
TASK_NAMES = (
    "assembly-v3",
    "basketball-v3",
    "bin-picking-v3",
    "box-close-v3",
    "button-press-topdown-v3",
    "button-press-topdown-wall-v3",
    "button-press-v3",
    "button-press-wall-v3",
    "coffee-button-v3",
    "coffee-pull-v3",
    "coffee-push-v3",
    "dial-turn-v3",
    "disassemble-v3",
    "door-close-v3",
    "door-lock-v3",
    "door-open-v3",
    "door-unlock-v3",
    "hand-insert-v3",
    "drawer-close-v3",
    "drawer-open-v3",
    "faucet-open-v3",
    "faucet-close-v3",
    "hammer-v3",
    "handle-press-side-v3",
    "handle-press-v3",
    "handle-pull-side-v3",
    "handle-pull-v3",
    "lever-pull-v3",
    "pick-place-wall-v3",
    "pick-out-of-hole-v3",
    "pick-place-v3",
    "plate-slide-v3",
    "plate-slide-side-v3",
    "plate-slide-back-v3",
    "plate-slide-back-side-v3",
    "peg-insert-side-v3",
    "peg-unplug-side-v3",
    "soccer-v3",
    "stick-push-v3",
    "stick-pull-v3",
    "push-v3",
    "push-wall-v3",
    "push-back-v3",
    "reach-v3",
    "reach-wall-v3",
    "shelf-place-v3",
    "sweep-into-v3",
    "sweep-v3",
    "window-open-v3",
    "window-close-v3",
)
# Meta-World's MT10 (metaworld.env_dict.MT10_V3)
MT10_TASK_NAMES = (
    "reach-v3",
    "push-v3",
    "pick-place-v3",
    "door-open-v3",
    "drawer-open-v3",
    "drawer-close-v3",
    "button-press-topdown-v3",
    "peg-insert-side-v3",
    "window-open-v3",
    "window-close-v3",
)
# The weld row Meta-World's reset_mocap_welds writes: anchor 0, relative position 0, relative quaternion (-1, 0, 0, 0),
# torque scale 5
_MOCAP_WELD = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 5.0)


def installed() -> bool:
    """Whether ``metaworld`` can be imported (looked up without importing it)."""
    return importlib.util.find_spec("metaworld") is not None


def metaworld_env_id(name: str) -> str:
    """The Gymnasium id this package registers for a Meta-World task, e.g. ``GenRL/metaworld-push-v3``.

    Meta-World registers no id per task (only benchmark ids such as ``Meta-World/MT1``, which draw each reset's task
    from a fixed list of 50 and ignore ``reset(seed=...)``), so these ids are the package's own.

    :param name: one of :data:`TASK_NAMES`, e.g. ``"push-v3"``
    """
    check_task_name(name)
    return f"GenRL/metaworld-{name}"


def check_task_name(name: str) -> None:
    """Raise a ``ValueError`` naming ``name`` and the 50 task names when it is not one of them."""
    if name not in TASK_NAMES:
        raise ValueError(f"unknown Meta-World task {name!r}; expected one of {sorted(TASK_NAMES)}")


def _import_metaworld() -> Any:
    # an optional extra, and ~1 s to import: only when a Meta-World env or expert is made
    try:
        import metaworld
    except ImportError as error:
        raise ImportError(f"{INSTALL_HINT} ({error})") from error
    return metaworld


def reset_mocap_welds(env: Any) -> None:
    """Meta-World's ``SawyerMocapBase.reset_mocap_welds`` for any width of ``model.eq_data``: the same 11 numbers in
    every weld row, and 0 in the numbers after them (MuJoCo 4.0.1 has 12 a row; see the module docstring).

    :param env: a Meta-World env (``env.model`` is its ``mujoco.MjModel``)
    """
    model = env.model
    if model.nmocap == 0 or model.eq_data is None:
        return
    for row in range(model.eq_data.shape[0]):
        if model.eq_type[row] == mujoco.mjtEq.mjEQ_WELD:
            model.eq_data[row, : len(_MOCAP_WELD)] = _MOCAP_WELD
            model.eq_data[row, len(_MOCAP_WELD) :] = 0.0


class SeededMetaWorldEnv:
    """What this package's Meta-World envs add to Meta-World's class of the task (a mixin placed before it).

    ## Description
    A Meta-World v3 task as Meta-World defines it (its model, observation, reward and ``info["success"]``), with the
    goal observed, the MuJoCo fix of :func:`reset_mocap_welds`, and resets that draw the task from the env's random
    generator, which ``reset(seed=...)`` reseeds.

    ## Action Space
    Meta-World's ``Box(-1, 1, (4,))``: the gripper's displacement in x, y, z (1 cm a unit) and its closing effort.

    ## Observation Space
    Meta-World's 39 numbers: the hand's position and the gripper's opening, the objects' positions and quaternions
    (padded to 14), the same 18 numbers of the previous step, and the goal's position.

    ## Rewards
    Meta-World's shaped reward (version ``v2`` by default), between 0 and 10, except at the step that ends an episode at
    its first success, which earns 10 (:data:`SOLVED_REWARD`, with the ``v2`` rewards), so that an episode's last reward
    ranks every solved episode above every unsolved one (the training env, ``terminate_on_success=False``, gives
    Meta-World's reward at every step).

    ## Starting State
    The object and goal positions drawn uniformly from the task's ``_random_reset_space`` by ``np_random``.

    ## Episode End
    Terminated at the first step at which the task is solved (Meta-World's evaluation protocol; see the module
    docstring), unless ``terminate_on_success=False``; truncated after 500 steps (``max_episode_steps`` of the
    registered ids). ``info["success"]`` says whether the task is solved at this step, ``info["is_success"]`` whether it
    has been at some step of the episode so far (Meta-World's measure of an episode).

    ## Arguments
    ``terminate_on_success`` (default True); Meta-World's: ``render_mode``, ``camera_name``, ``camera_id``,
    ``reward_function_version`` (``"v2"``), ``height`` and ``width`` (480) of rendered images.
    """

    def __init__(self, terminate_on_success: bool = True, **kwargs: Any) -> None:
        if not isinstance(terminate_on_success, bool | np.bool_):
            raise ValueError(f"terminate_on_success must be True or False, got {terminate_on_success!r}")
        super().__init__(**kwargs)
        self.terminate_on_success = bool(terminate_on_success)
        self._solved = False  # whether the task has been solved at some step of this episode
        self._partially_observable = False  # the goal in the observation, as in Meta-World's MT benchmarks
        self.__dict__.pop("sawyer_observation_space", None)  # a cached property, computed with the goal hidden
        self.observation_space = self.sawyer_observation_space
        self._freeze_rand_vec = False  # a new task at each reset...
        self.seeded_rand_vec = True  # ... drawn from self.np_random, not from numpy's global generator
        self._set_task_called = True  # no Task object: the task is the reset's draw

    def reset_mocap_welds(self) -> None:
        """Meta-World's method with MuJoCo 4.0's 12 numbers an equality row (:func:`reset_mocap_welds`)."""
        reset_mocap_welds(self)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Draw a task (from ``np_random``, reseeded by ``seed``) and return its first observation and ``info``."""
        if seed is not None:
            gym.Env.reset(self, seed=seed)  # Gymnasium's seeding of np_random, which Meta-World's reset skips
        self._solved = False
        return super().reset(options=options)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Meta-World's step, with ``info["is_success"]``: whether the task has been solved at some step of the episode
        so far; terminated at a success when ``terminate_on_success`` (as Meta-World's
        ``AutoTerminateOnSuccessWrapper``), with the reward :data:`SOLVED_REWARD` (``v2`` rewards)."""
        observation, reward, terminated, truncated, info = super().step(action)
        solved_now = info["success"] == 1.0
        self._solved = self._solved or solved_now
        info["is_success"] = self._solved
        if self.terminate_on_success:
            terminated = bool(terminated or solved_now)
            if solved_now and self.reward_function_version == "v2":
                reward = SOLVED_REWARD
        return observation, reward, terminated, truncated, info


@functools.cache
def task_class(name: str) -> type:
    """This package's env class of a Meta-World task: :class:`SeededMetaWorldEnv` on Meta-World's class of it.

    :param name: one of :data:`TASK_NAMES`
    """
    check_task_name(name)
    base = _import_metaworld().env_dict.ALL_V3_ENVIRONMENTS[name]
    return type(f"Seeded{base.__name__}", (SeededMetaWorldEnv, base), {"__module__": __name__})


def _env_arguments(name: str) -> tuple[str, ...]:
    """The keyword arguments Meta-World's class of ``name`` takes."""
    base = _import_metaworld().env_dict.ALL_V3_ENVIRONMENTS[name]
    return tuple(parameter for parameter in inspect.signature(base.__init__).parameters if parameter != "self")


def seeded_env(name: str, **kwargs: Any) -> gym.Env:
    """The env of a Meta-World task without wrappers (the entry point of the registered ids; use
    :func:`make_metaworld_env` or ``gymnasium.make`` for the 500-step limit).

    :param name: one of :data:`TASK_NAMES`
    :param kwargs: ``terminate_on_success`` and the arguments of Meta-World's env class (``render_mode``,
        ``camera_name``, ``camera_id``, ``reward_function_version``, ``height``, ``width``)
    """
    return task_class(name)(**kwargs)


def register_metaworld_envs() -> tuple[str, ...]:
    """Register ``GenRL/metaworld-<name>`` for each of the 50 tasks when ``metaworld`` can be imported (idempotent;
    ``metaworld`` is not imported). Returns the ids registered by now (none without Meta-World)."""
    if not installed():
        return ()
    env_ids = tuple(metaworld_env_id(name) for name in TASK_NAMES)
    for name, env_id in zip(TASK_NAMES, env_ids, strict=True):
        if env_id not in registry:
            register(
                id=env_id,
                entry_point=f"{__name__}:seeded_env",
                kwargs={"name": name},
                max_episode_steps=MAX_EPISODE_STEPS,
            )
    return env_ids


def make_metaworld_env(name: str, **kwargs: Any) -> gym.Env:
    """A Meta-World v3 task as a Gymnasium env: seeded resets, ``info["is_success"]`` (solved at some step so far), an
    episode ending at its first success or after 500 steps.

    The same as ``gymnasium.make(metaworld_env_id(name), **kwargs)``; see :class:`SeededMetaWorldEnv` for what the env
    is and the module docstring for what it fixes.

    :param name: the task, one of :data:`TASK_NAMES` (e.g. ``"push-v3"``)
    :param kwargs: ``terminate_on_success`` (default True; False: Meta-World's training env, which runs on after a
        success) and the arguments of Meta-World's env class (``render_mode``, ``camera_name``,
        ``camera_id``, ``reward_function_version``, ``height``, ``width``)
    :return: the env, in a ``TimeLimit`` of :data:`MAX_EPISODE_STEPS`
    """
    check_task_name(name)
    if not installed():
        raise ImportError(INSTALL_HINT)
    accepted = ("terminate_on_success", *_env_arguments(name))
    unknown = sorted(set(kwargs) - set(accepted))
    if unknown:
        raise ValueError(f"unknown argument(s) {unknown} of Meta-World task {name!r}; expected some of {list(accepted)}")
    register_metaworld_envs()
    return gym.make(metaworld_env_id(name), **kwargs)


class MetaWorldExpert:
    """Meta-World's scripted policy of a task (``metaworld.policies``) as a function of the observation.

    Its actions are clipped to the action space (the env clips the displacement and MuJoCo the gripper's command to
    the same range) and returned as ``float32``; Meta-World's warning that a policy's gains may be too high is silenced.

    :param name: one of :data:`TASK_NAMES`
    """

    def __init__(self, name: str) -> None:
        check_task_name(name)
        _import_metaworld()
        from metaworld.policies import ENV_POLICY_MAP  # the optional extra, imported with it above

        self.name = name
        self.policy = ENV_POLICY_MAP[name]()

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """The action (4 numbers in [-1, 1]) for a 39-D observation of the task's env."""
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r"Constant\(s\) may be too high", category=UserWarning)
            # a copy: the door-open-v3 policy shifts the handle's position in its observation in place (metaworld
            # 3.1.1, metaworld/policies/sawyer_door_open_v3_policy.py), which would change the caller's observation
            action = self.policy.get_action(np.array(observation, dtype=np.float64, copy=True))
        return np.clip(action, -1.0, 1.0).astype(np.float32)


def metaworld_expert(name: str) -> MetaWorldExpert:
    """Meta-World's scripted expert of a task: observation -> action (:class:`MetaWorldExpert`).

    :param name: one of :data:`TASK_NAMES` (e.g. ``"push-v3"``)
    """
    return MetaWorldExpert(name)
