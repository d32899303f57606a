"""The latent-action wrapper: an episodic task seen as a one-step contextual bandit (paper section 4).

The paper replaces the task's MDP by one whose action is the latent action ``alpha`` of a generative model and
whose horizon is one: observe the context ``s0`` (e.g. the goal), choose ``alpha``, decode it into a whole
open-loop trajectory ``tau = g(alpha)``, play ``tau`` and receive the terminal reward ``r(s0, tau)``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

from sb3_genrl.checks import check_positive_float
from sb3_genrl.generative.base import TrajectoryGenerator

RewardMode = Literal["last", "sum"]


def task_has_fast_path(task: gym.Env) -> bool:
    """Whether a task (an env, unwrapped) has the fast open-loop path of the GenRL tasks: ``play_trajectories`` (one
    MuJoCo rollout for a whole trajectory, many at once) and ``get_context``."""
    return hasattr(task, "play_trajectories") and hasattr(task, "get_context")


def env_id_has_fast_path(env_id: str) -> bool:
    """Whether the task registered as ``env_id`` has the fast path (:func:`task_has_fast_path`); the env is made to
    tell, and closed."""
    env = gym.make(env_id)
    try:
        return task_has_fast_path(env.unwrapped)
    finally:
        env.close()


class LatentActionWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Turn an episodic Gymnasium env with per-step actions into a one-step bandit over a generator's latent space.

    ``reset()`` resets the wrapped env and observes the task context. ``step(alpha)`` decodes ``alpha`` into a
    ``(horizon, action_dim)`` trajectory, plays it and ends the episode (``terminated=True``, ``truncated=False``):
    one episode is one bandit pull. When ``env.unwrapped`` has ``play_trajectories(trajectories, goals)`` and
    ``get_context()`` (the GenRL tasks), the trajectory is played through that fast open-loop path for the
    current goal (the task's own ``goal`` attribute when it has one, so that the reward is exactly the step
    path's); otherwise it is played step by step through ``env`` and, if the episode has not ended when the
    trajectory does, the arm holds still (``hold_action``) until it ends or for at most ``max_hold_steps`` steps.

    A ``gymnasium.Wrapper``: ``unwrapped`` is the task, ``render_mode``, ``render()``, ``metadata`` and ``spec``
    are the wrapped env's, and SB3's ``VecEnv.get_attr`` / ``env_method`` reach the task's attributes and methods.
    The constructor arguments are recorded in ``spec``, so ``env.spec.make()`` rebuilds the wrapped env.
    A task that declares its ``horizon`` (an integer attribute of ``env.unwrapped``) must have the generator's.

    Observation: the task context. For envs with ``get_context()`` and ``context_space`` the goal; with a
    ``context`` callable ``context(reset_obs)`` (and its ``context_space``); for a goal-conditioned env (see below)
    the reset observation's ``desired_goal`` followed by its ``observation``, flattened, as one ``Box``; otherwise the
    reset observation.

    Goal-conditioned envs (Gymnasium-Robotics' ``GoalEnv`` convention: a ``Dict`` observation with ``observation``,
    ``achieved_goal`` and ``desired_goal``, and ``env.unwrapped.compute_reward(achieved_goal, desired_goal, info)``)
    need nothing else. Their context is ``Box`` so that GenRL's policy reads it as one vector (scaled by
    :class:`~sb3_genrl.genrl.policies.BoxScaler` where bounded) and its hindsight relabelling can put another goal in
    it; an open-loop trajectory depends on the whole reset state (e.g. where the object starts), not only on the goal.
    The step's ``info["hindsight"]`` is derived from the API alone: the context with the last achieved goal as
    desired goal (the reset observation unchanged), and the reward the episode would have earned for it, by
    ``compute_reward`` of each step played (the last step's, or their sum with ``reward="sum"``); ``None`` (not
    relabelled) when the achieved goal at the start already earns that reward: the trajectory moved nothing. The episode's
    success, ``info["is_success"]`` of its last step when the env reports it, is in the step's info, so SB3's
    algorithms (GenRL included) log ``rollout/success_rate``.

    Action: the latent action, ``Box(-1, 1)`` for a uniform prior and ``Box(-latent_clip, latent_clip)`` for a
    normal prior (``+-3`` standard deviations by default). Actions outside the box are clipped, and the clip is
    reported in ``info["latent_clipped"]``.

    ``info`` after ``step``: the task's own trajectory summary (e.g. ``table_contacts``, ``reached``,
    ``unstable`` for the GenRL tasks) plus ``reward``, ``steps_played`` (trajectory steps played),
    ``hold_steps``, ``ended`` (whether the wrapped episode ended), ``latent_clipped`` and ``fast_path``. When the
    context is the task's ``get_context()`` and the task has a method ``hindsight(info)``, also ``hindsight``: what it
    returns for the step's info, ``(context', reward')`` (a context this trajectory solves, and its reward there) or
    ``None``; :class:`~sb3_genrl.GenRL` relabels pulls with it when given ``hindsight_kwargs``.

    :param env: the episodic task; its per-step action shape must be ``(generator.action_dim,)``
    :param generator: the trajectory generator (see :class:`~sb3_genrl.generative.TrajectoryGenerator`)
    :param context: ``None`` (the task's ``get_context()`` or the reset observation) or a callable mapping the
        reset observation to the context array; a callable needs ``context_space``
    :param context_space: the observation space of the ``context`` callable's output
    :param reward: ``"last"`` (the reward of the last step played, the terminal reward; default) or ``"sum"``
        (the sum of the rewards over the steps played, holding included)
    :param latent_clip: half-width of the action box for a normal prior, in prior standard deviations (default 3)
    :param hold_action: the per-step action played after the trajectory (step-by-step path); default zeros
    :param max_hold_steps: at most this many hold steps after the trajectory (step-by-step path; default 1000)
    :param use_fast_path: ``None`` (default): use ``play_trajectories`` when the task has it; ``False``: always
        play step by step; ``True``: require the fast path
    """

    def __init__(
        self,
        env: gym.Env,
        generator: TrajectoryGenerator,
        *,
        context: Callable[[Any], np.ndarray] | None = None,
        context_space: spaces.Space | None = None,
        reward: RewardMode = "last",
        latent_clip: float = 3.0,
        hold_action: np.ndarray | None = None,
        max_hold_steps: int = 1000,
        use_fast_path: bool | None = None,
    ) -> None:
        if not isinstance(env, gym.Env):
            raise TypeError(f"env must be a gymnasium.Env, got {type(env).__name__}")
        if not isinstance(generator, TrajectoryGenerator):
            raise TypeError(f"generator must be a TrajectoryGenerator, got {type(generator).__name__}")
        if reward not in ("last", "sum"):
            raise ValueError(f"reward must be 'last' or 'sum', got {reward!r}")
        check_positive_float(latent_clip, "latent_clip")
        if int(max_hold_steps) != max_hold_steps or max_hold_steps < 0:
            raise ValueError(f"max_hold_steps must be a non-negative integer, got {max_hold_steps!r}")
        gym.utils.RecordConstructorArgs.__init__(
            self,
            _disable_deepcopy=True,  # the spec holds this generator, not a copy of the model per env
            generator=generator,
            context=context,
            context_space=context_space,
            reward=reward,
            latent_clip=latent_clip,
            hold_action=hold_action,
            max_hold_steps=max_hold_steps,
            use_fast_path=use_fast_path,
        )
        gym.Wrapper.__init__(self, env)
        self.generator = generator
        self.reward_mode: RewardMode = reward
        self.latent_clip = float(latent_clip)
        self.max_hold_steps = int(max_hold_steps)
        self.hold_action = self._checked_hold_action(hold_action)
        self.use_fast_path = self._checked_fast_path(use_fast_path)
        self._context_source: Callable[[Any], Any] | str
        self._context_source, self.observation_space = self._context_setup(context, context_space)

        # Action: the latent action alpha, boxed to the prior's support (uniform) or +-latent_clip sigma (normal).
        bound = 1.0 if generator.prior == "uniform" else self.latent_clip
        self.action_space = spaces.Box(-bound, bound, shape=(generator.latent_dim,), dtype=np.float32)
        self._needs_reset = True
        self._prepared: tuple[np.ndarray, dict[str, Any]] | None = None  # see prepare_step
        self._reset_seeds: Callable[[int], int] | None = None  # see set_reset_seeds
        self._episode = 0  # the episodes reset since set_reset_seeds (the first one: its `first`)

    def _checked_hold_action(self, hold_action: np.ndarray | None) -> np.ndarray:
        """Check that the env's per-step actions are the generator's rows; return the hold action in the env's dtype."""
        env, generator = self.env, self.generator
        # Per-step actions: the generator's (T, M) trajectory is played one row (M numbers) per step.
        step_shape = (generator.action_dim,)
        env_shape = getattr(env.action_space, "shape", None)
        if not isinstance(env.action_space, spaces.Box) or env_shape != step_shape:
            raise ValueError(
                f"generator trajectories of shape (T, M) = ({generator.horizon}, {generator.action_dim}) give per-step "
                f"actions of shape {step_shape}, but the env's action space is {env.action_space} with shape {env_shape}"
            )
        hold = np.zeros(step_shape, dtype=env.action_space.dtype) if hold_action is None else np.asarray(hold_action)
        if hold.shape != step_shape:
            raise ValueError(f"hold_action must have the env's action shape {step_shape}, got {hold.shape}")
        return hold.astype(env.action_space.dtype)

    def _checked_fast_path(self, use_fast_path: bool | None) -> bool:
        """Check the task's horizon against the generator's; return whether trajectories are played by the fast path."""
        task, generator = self.env.unwrapped, self.generator
        task_horizon = getattr(task, "horizon", None)
        if isinstance(task_horizon, int | np.integer) and task_horizon != generator.horizon:
            raise ValueError(
                f"the generator's trajectories have horizon T = {generator.horizon} time steps, but "
                f"{type(task).__name__} has horizon {task_horizon}; use a generator trained on this task"
            )
        has_fast_path = task_has_fast_path(task)
        limit = getattr(self.env.spec, "max_episode_steps", None)  # gymnasium.make's TimeLimit, if any
        if limit is not None and limit < generator.horizon and not has_fast_path:
            raise ValueError(
                f"the generator's trajectories have horizon T = {generator.horizon} time steps, but the env's episodes "
                f"end after {limit} (its max_episode_steps): every trajectory would be cut short; use a generator of "
                f"at most {limit} steps, or make the env with max_episode_steps={generator.horizon}"
            )
        if use_fast_path and not has_fast_path:
            raise ValueError(f"use_fast_path=True but {type(task).__name__} has no play_trajectories()/get_context()")
        return has_fast_path if use_fast_path is None else bool(use_fast_path)

    def _context_setup(
        self, context: Callable[[Any], np.ndarray] | None, context_space: spaces.Space | None
    ) -> tuple[Callable[[Any], Any] | str, spaces.Space]:
        """Return the source of the task context s0 (the callable, ``"task"`` or ``"observation"``) and its space."""
        task = self.env.unwrapped
        if context is not None:
            if not callable(context) or context_space is None:
                raise ValueError("context must be a callable context(reset_obs) -> array, given with context_space")
            return context, context_space
        if context_space is not None and not (hasattr(task, "get_context") and hasattr(task, "context_space")):
            raise ValueError("context_space is only used together with a context callable")
        return default_context(self.env)

    def _observe(self, obs: Any) -> Any:
        if self._context_source == "task":
            context = self.env.unwrapped.get_context()
        elif self._context_source == "observation":
            context = obs
        elif self._context_source == "goal":
            context = goal_context(obs)
        else:
            context = self._context_source(obs)  # type: ignore[operator]
        if isinstance(self.observation_space, spaces.Box):
            context = np.array(context, dtype=self.observation_space.dtype).reshape(self.observation_space.shape)
        return context

    def set_reset_seeds(self, seeds: Callable[[int], int] | None, first: int = 0) -> None:
        """Reset the task with ``seeds(k)`` at its ``k``-th reset from now on (``k = first, first + 1, ...``), whatever
        seed the reset is given: GenRL's groups of pulls from one context
        (:class:`~sb3_genrl.genrl.grouped_pulls.ContextSeeds`). ``None``: the resets' own seeds again.

        :param seeds: the reset seed of each episode, or None
        :param first: the index of the next reset's episode
        """
        self._reset_seeds, self._episode = seeds, int(first)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Reset the wrapped task (``options``, e.g. ``{"goal": xy}``, are passed on when given) and observe its context;
        with :meth:`set_reset_seeds`, the task resets with the episode's seed instead of ``seed``."""
        if self._reset_seeds is not None:
            seed, self._episode = self._reset_seeds(self._episode), self._episode + 1
        obs, info = self.env.reset(seed=seed) if options is None else self.env.reset(seed=seed, options=options)
        self._context = self._observe(obs)
        self._start_achieved = copy.deepcopy(obs["achieved_goal"]) if self._context_source == "goal" else None
        self._needs_reset = False
        self._prepared = None
        return copy.deepcopy(self._context), dict(info)

    def check_action(self, alpha: np.ndarray) -> tuple[np.ndarray, bool]:
        """Return ``alpha`` as a finite ``(latent_dim,)`` array clipped to the action box, and whether it was clipped."""
        alpha = np.asarray(alpha, dtype=np.float32)
        if alpha.shape != self.action_space.shape:
            raise ValueError(f"latent action must have shape {self.action_space.shape}, got {alpha.shape}")
        if not np.all(np.isfinite(alpha)):
            raise ValueError(f"latent action contains non-finite values (nan or inf): {alpha}")
        clipped = np.clip(alpha, self.action_space.low, self.action_space.high)
        return clipped, bool(np.any(clipped != alpha))

    def trajectory(self, alpha: np.ndarray) -> np.ndarray:
        """Decode one latent action (clipped to the action box) into its ``(horizon, action_dim)`` trajectory, as ``step``
        and :class:`~sb3_genrl.vec_env.BatchedLatentVecEnv` play it."""
        alpha, _ = self.check_action(alpha)
        return self._decode(alpha[None])[0]

    def _decode(self, alphas: np.ndarray) -> np.ndarray:
        g = self.generator
        trajectories = np.asarray(g.decode(g.check_latent(alphas)))
        expected = (len(alphas), g.horizon, g.action_dim)
        if trajectories.shape != expected:
            raise ValueError(f"generator.decode returned shape {trajectories.shape}, expected {expected}")
        return trajectories

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Decode ``action`` (the latent action), play the whole trajectory and end the episode."""
        if self._needs_reset:
            raise RuntimeError("LatentActionWrapper: call reset() before step(); each episode is a single step")
        alpha, latent_clipped = self.check_action(action)
        prepared, self._prepared = self._prepared, None
        if prepared is not None and np.array_equal(prepared[0], alpha):  # already played (prepare_step)
            info = prepared[1]
        elif self.use_fast_path:
            info = self._play_fast(self.trajectory(alpha))
        else:
            info = self._play_steps(self.trajectory(alpha))
        info["latent_clipped"] = latent_clipped
        if not np.isfinite(info["reward"]):  # refused here: a NaN would silently stall any learner downstream
            raise ValueError(
                f"{type(self.env.unwrapped).__name__} returned the non-finite reward {info['reward']!r} for "
                f"the latent action {alpha.tolist()} (context {np.asarray(self._context).tolist()}); a reward "
                "must be a finite number"
            )
        relabel = getattr(self.env.unwrapped, "hindsight", None)
        if self._context_source == "task" and callable(relabel):  # for GenRL's hindsight_kwargs
            info["hindsight"] = relabel(info)
        elif self._context_source == "goal":
            info["hindsight"] = self._goal_hindsight(info.pop("goal_steps", []))
        self._needs_reset = True
        return copy.deepcopy(self._context), info["reward"], True, False, info

    def fast_path_goal(self) -> np.ndarray:
        """The current episode's goal as the fast path plays it: the task's own (float64) ``goal`` when it has one
        (``get_context()`` may round it), else its context."""
        task = self.env.unwrapped
        goal = getattr(task, "goal", None)
        return np.asarray(task.get_context() if goal is None else goal, dtype=np.float64)

    def prepare_step(self, alpha: np.ndarray, reward: float, info: dict[str, Any]) -> None:
        """Hand the next ``step`` the result of ``alpha`` (a checked latent action) played elsewhere for the current
        episode through the task's ``play_trajectories`` (its reward and info): a ``step`` with that very action
        returns it instead of playing it again (:class:`~sb3_genrl.vec_env.BatchedLatentVecEnv` plays all its envs'
        actions in one call); any other action is played as usual."""
        self._prepared = (np.array(alpha, dtype=np.float32), self._fast_path_info(reward, info))

    def _play_fast(self, tau: np.ndarray) -> dict[str, Any]:
        rewards, infos = self.env.unwrapped.play_trajectories(tau[None], self.fast_path_goal()[None])
        return self._fast_path_info(rewards[0], infos[0])

    def _fast_path_info(self, reward: float, info: dict[str, Any]) -> dict[str, Any]:
        """A step's info from one trajectory's fast-path result: the task's info with the step path's keys."""
        return {
            **info,
            "reward": float(reward),
            "steps_played": self.generator.horizon,
            "hold_steps": 0,
            "ended": True,
            "fast_path": True,
        }

    def _play_steps(self, tau: np.ndarray) -> dict[str, Any]:
        rewards: list[float] = []
        info: dict[str, Any] = {}
        goal_steps: list[tuple[Any, dict[str, Any]]] = []  # a goal env's achieved goal and info after each step
        ended = False
        steps_played = hold_steps = 0
        for u in tau:
            obs, r, terminated, truncated, info = self.env.step(u.astype(self.env.action_space.dtype))
            self._keep_goal_step(goal_steps, obs, info)
            rewards.append(float(r))
            steps_played += 1
            if terminated or truncated:
                ended = True
                break
        while not ended and hold_steps < self.max_hold_steps:  # hold still until the task ends
            obs, r, terminated, truncated, info = self.env.step(self.hold_action.copy())
            self._keep_goal_step(goal_steps, obs, info)
            rewards.append(float(r))
            hold_steps += 1
            ended = bool(terminated or truncated)
        reward = rewards[-1] if self.reward_mode == "last" else float(np.sum(rewards))
        info = dict(info)
        info.update(reward=float(reward), steps_played=steps_played, hold_steps=hold_steps, ended=ended, fast_path=False)
        if self._context_source == "goal":
            info["goal_steps"] = goal_steps
        return info

    def _keep_goal_step(self, goal_steps: list[tuple[Any, dict[str, Any]]], obs: Any, info: dict[str, Any]) -> None:
        if self._context_source == "goal":
            goal_steps.append((copy.deepcopy(obs["achieved_goal"]), info))

    def _goal_hindsight(self, goal_steps: list[tuple[Any, dict[str, Any]]]) -> tuple[np.ndarray, float] | None:
        """A goal env's relabelled pull: the context with the last achieved goal as desired goal, and the reward of
        the steps played for that goal by ``compute_reward`` (the last step's, or the sum with ``reward="sum"``);
        ``None`` when the achieved goal at the start already earns the end's reward (the trajectory moved nothing)."""
        if not goal_steps:
            return None
        new_goal = goal_steps[-1][0]
        # a trajectory that leaves the achieved goal where it started (a push that misses the object) solves its
        # relabelled goal whatever it does: such a pull teaches nothing about reaching goals
        last_info = goal_steps[-1][1]
        if self._goal_reward(self._start_achieved, new_goal, last_info) >= self._goal_reward(new_goal, new_goal, last_info):
            return None
        rewards = [
            self._goal_reward(achieved, new_goal, info)
            for achieved, info in (goal_steps[-1:] if self.reward_mode == "last" else goal_steps)
        ]
        desired = np.ravel(new_goal).astype(np.float32)
        return np.concatenate([desired, np.asarray(self._context, np.float32)[desired.size :]]), float(np.sum(rewards))

    def _goal_reward(self, achieved_goal: Any, desired_goal: Any, info: dict[str, Any]) -> float:
        """A goal env's ``compute_reward`` for one achieved goal and one desired goal, refused unless it is one finite
        number (a NaN would reach the E-step through the relabelled pulls)."""
        task = self.env.unwrapped
        reward = np.asarray(task.compute_reward(achieved_goal, desired_goal, info))
        if reward.size != 1:
            raise ValueError(
                f"{type(task).__name__}.compute_reward(achieved_goal, desired_goal, info) returned shape {reward.shape} "
                f"for one achieved goal of shape {np.shape(achieved_goal)} and one desired goal: expected one reward "
                "(shape () or (1,))"
            )
        if not np.isfinite(reward.item()):
            raise ValueError(
                f"{type(task).__name__}.compute_reward(achieved_goal, desired_goal, info) returned the non-finite "
                f"reward {reward.item()!r} for the achieved goal {np.ravel(achieved_goal).tolist()} and the desired "
                f"goal {np.ravel(desired_goal).tolist()} (a relabelled pull of hindsight); a reward must be a finite "
                "number"
            )
        return float(reward.item())

    def play_batch(self, alphas: np.ndarray, goals: np.ndarray, *, n_threads: int = 1) -> tuple[np.ndarray, list[dict]]:
        """Play many latent actions ``(B, latent_dim)`` for goals ``(B, goal_dim)`` through the task's fast path.

        Does not touch the current episode. Returns the ``(B,)`` terminal rewards and one info dict per trajectory.
        Needs a task with ``play_trajectories`` (raises ``ValueError`` otherwise); actions are clipped to the box.
        """
        task = self.env.unwrapped
        if not hasattr(task, "play_trajectories"):
            raise ValueError(f"{type(task).__name__} has no play_trajectories(); play_batch needs the fast path")
        alphas = self.generator.check_latent(alphas)
        goals = np.asarray(goals, dtype=np.float64)
        if goals.ndim != 2 or len(goals) != len(alphas):
            raise ValueError(f"goals must have shape ({len(alphas)}, goal_dim), got {goals.shape}")
        alphas = np.clip(alphas, self.action_space.low, self.action_space.high)
        rewards, infos = task.play_trajectories(self._decode(alphas), goals, n_threads=n_threads)
        return np.asarray(rewards, dtype=np.float64), list(infos)


GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")


def default_context(env: gym.Env) -> tuple[str, spaces.Space]:
    """Where :class:`LatentActionWrapper` takes ``env``'s context from when it is given no ``context`` callable, and
    the context's space: the task's ``get_context()`` (``"task"``), a goal-conditioned env's goal and observation as
    one Box (``"goal"``), else the reset observation (``"observation"``)."""
    task = env.unwrapped
    if hasattr(task, "get_context") and hasattr(task, "context_space"):
        return "task", task.context_space
    if is_goal_env(env):
        return "goal", goal_context_space(env.observation_space)
    return "observation", env.observation_space


def is_goal_env(env: gym.Env) -> bool:
    """Whether ``env`` follows Gymnasium-Robotics' ``GoalEnv`` convention: a ``Dict`` observation space with
    ``observation``, ``achieved_goal`` and ``desired_goal``, and ``env.unwrapped.compute_reward``."""
    space = env.observation_space
    return (
        isinstance(space, spaces.Dict)
        and all(isinstance(space.spaces.get(key), spaces.Box) for key in GOAL_KEYS)
        and callable(getattr(env.unwrapped, "compute_reward", None))
    )


def goal_context_space(space: spaces.Dict) -> spaces.Box:
    """The ``Box`` of a goal env's context: ``desired_goal`` then ``observation``, flattened, with their bounds."""
    parts = [space[key] for key in ("desired_goal", "observation")]
    low = np.concatenate([np.ravel(part.low) for part in parts]).astype(np.float32)
    high = np.concatenate([np.ravel(part.high) for part in parts]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


def goal_context(observation: dict[str, Any]) -> np.ndarray:
    """A goal env's context from its reset observation: ``desired_goal`` then ``observation``, flattened (float32)."""
    return np.concatenate([np.ravel(observation[key]) for key in ("desired_goal", "observation")]).astype(np.float32)


def find_latent_wrapper(env: gym.Env) -> LatentActionWrapper | None:
    """The :class:`LatentActionWrapper` in ``env``'s chain of wrappers (``env`` itself included), or ``None``."""
    while True:
        if isinstance(env, LatentActionWrapper):
            return env
        if not isinstance(env, gym.Wrapper):
            return None
        env = env.env


def latent_action_env(
    env: gym.Env | VecEnv | str | None,
    generator: TrajectoryGenerator | None,
    *,
    latent_clip: float = 3.0,
    check_latent_clip: bool = True,
) -> tuple[gym.Env | VecEnv | None, TrajectoryGenerator | None]:
    """Return ``(env, generator)`` with ``env`` a latent-action env (used by GenRL for what users pass it).

    A raw env (or Gymnasium id) is wrapped in :class:`LatentActionWrapper`; an env that already is one (possibly
    inside further wrappers), or a VecEnv of such envs, is returned as is, with its generator when none is given.
    ``None`` stays ``None``. Raises ``ValueError`` for a raw env without generator, a VecEnv of raw envs, a
    generator whose shapes differ from the wrapped env's, or (a normal prior, with ``check_latent_clip``) an env
    wrapped with another ``latent_clip``: GenRL's setting is the wrapped env's, not only a record.
    """
    if generator is not None and not isinstance(generator, TrajectoryGenerator):
        raise TypeError(f"generator must be a TrajectoryGenerator or a file path, got {type(generator).__name__}")
    if env is None:
        return None, generator
    if isinstance(env, str):
        env = gym.make(env)
    if isinstance(env, VecEnv):
        try:
            env_generator = env.get_attr("generator", indices=[0])[0]
        except AttributeError as error:
            raise ValueError("a VecEnv must hold LatentActionWrapper envs; wrap each env before vectorising") from error
        env_clip = _vec_env_attribute(env, "latent_clip")
    elif find_latent_wrapper(env) is not None:
        env_generator = find_latent_wrapper(env).generator  # type: ignore[union-attr]
        env_clip = find_latent_wrapper(env).latent_clip  # type: ignore[union-attr]
    else:
        if generator is None:
            raise ValueError(f"a generator is needed to wrap {env} (or pass an env already wrapped in LatentActionWrapper)")
        return LatentActionWrapper(env, generator, latent_clip=latent_clip), generator
    if not isinstance(env_generator, TrajectoryGenerator):
        raise ValueError("the env's generator attribute is not a TrajectoryGenerator")
    if generator is not None and generator is not env_generator:
        shapes = [(g.latent_dim, g.horizon, g.action_dim) for g in (generator, env_generator)]
        if shapes[0] != shapes[1]:
            raise ValueError(f"generator (latent_dim, T, M) = {shapes[0]} differs from the wrapped env's {shapes[1]}")
    if check_latent_clip and env_generator.prior != "uniform" and env_clip is not None and env_clip != latent_clip:
        raise ValueError(
            f"the env is wrapped with latent_clip={env_clip!r}, not {latent_clip!r}: the latent_clip of GenRL (or of "
            "the model) is the half-width of the wrapped env's action box; give both the same"
        )
    return env, generator if generator is not None else env_generator


def _vec_env_attribute(env: VecEnv, name: str) -> Any:
    """The attribute ``name`` of a VecEnv's first env, None when it has none."""
    try:
        return env.get_attr(name, indices=[0])[0]
    except AttributeError:
        return None
