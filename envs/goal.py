"""Goal-conditioned variants of the arm tasks for hindsight experience replay (``GenRL/HockeyGoal-v0``,
``GenRL/BasketballGoal-v0``: each task module declares its variant, ``TaskSpec.goal_env_class``).

Same physics, goals, actions and rewards as the plain tasks; the observation is a dict in the convention of
goal-conditioned envs (``observation``, ``achieved_goal``, ``desired_goal``) and the reward is computed by a
vectorised :meth:`GoalConditionedMixin.compute_reward`, so SB3's ``HerReplayBuffer`` can relabel goals.

**What the achieved goal is.** The plain tasks score an episode once it is over (the puck at rest; the ball's
crossings of the rim's height), so the achieved goal is only known at the terminal step:

- during the episode, ``achieved_goal`` is the object's current (x, y);
- at the terminal step it is ``info["reached"]``: hockey's rest point, basketball's crossing closest to the
  desired goal.

Every reward but the terminal one is 0, as in the plain tasks. ``compute_reward`` tells the terminal transition by
``info["terminal"]`` (so ``HerReplayBuffer`` must be made with ``copy_info_dict=True``), and is exact for *any*
relabelled goal: hockey's terminal reward is minus the distance from the rest point; basketball's is the smallest
distance over all crossings, which the terminal info stores (``info["crossing_points"]``, see
:class:`~sb3_genrl.envs.basketball.BasketballGoalEnv`), since the crossing that is best depends on the goal.
With HER's ``final`` strategy the relabelled goal is the terminal achieved goal and the terminal reward is 0; the
``future`` strategy would mostly relabel with mid-episode object positions, which no terminal transition of the
episode is scored against.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from sb3_genrl.envs.control import MAX_OBJECT_SPEED


class GoalConditionedMixin:
    """Turns an :class:`~sb3_genrl.envs.base.ArmTaskEnv` subclass into a goal-conditioned env (see the module).

    ``observation``: the 7 joint positions, 7 joint velocities and the remaining share of the episode ``1 - t / T``
    (the feature of sb3-contrib's ``TimeFeatureWrapper``: a terminal-only reward over a fixed horizon needs it to
    be Markovian); ``achieved_goal`` and ``desired_goal``: (x, y) in metres, float64, bounded by how far the object can travel.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        plain = self.observation_space
        joints = spaces.Box(
            np.append(plain.low[2:], 0.0).astype(np.float32),
            np.append(plain.high[2:], 1.0).astype(np.float32),
            dtype=np.float32,
        )
        # The object starts within 1 m of the robot and moves below MAX_OBJECT_SPEED (faster is flagged unstable)
        # for at most (horizon + settle_steps) control steps: a bound on where it can be.
        reach = 1.0 + MAX_OBJECT_SPEED * (self.horizon + self.settle_steps) * self.frame_skip * self.model.opt.timestep
        goal = spaces.Box(-reach, reach, shape=(2,), dtype=np.float64)
        self.observation_space = spaces.Dict({"observation": joints, "achieved_goal": goal, "desired_goal": goal})

    def _get_obs(self) -> dict[str, np.ndarray]:
        plain = super()._get_obs()
        return {
            "observation": np.append(plain[2:], np.float32(1 - self._t / self.horizon)),
            "achieved_goal": self.data.sensordata[1:3].copy(),
            "desired_goal": np.array(self.goal, dtype=np.float64),
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = super().reset(seed=seed, options=options)
        return obs, info | {"terminal": False}

    def step(self, action):
        obs, _, terminated, truncated, info = super().step(action)
        info = dict(info, terminal=bool(terminated))
        if terminated and "reached" in info:
            obs["achieved_goal"] = np.asarray(info["reached"], dtype=np.float64)
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        return obs, reward, terminated, truncated, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray | float:
        """The reward of transitions for (relabelled) goals: 0 unless ``info["terminal"]``, else the plain task's
        terminal reward for ``desired_goal``.

        :param achieved_goal: ``(2,)`` or ``(B, 2)`` achieved goals (the next observation's)
        :param desired_goal: the goals, same shape
        :param info: the transition's info dict, or a sequence of ``B`` of them
        :return: a float for one transition, ``(B,)`` rewards for a batch
        """
        achieved = np.asarray(achieved_goal, dtype=np.float64)
        desired = np.asarray(desired_goal, dtype=np.float64)
        single = achieved.ndim == 1
        achieved, desired = np.atleast_2d(achieved), np.atleast_2d(desired)
        infos = [info] if isinstance(info, dict) else list(info)
        if achieved.shape != desired.shape or achieved.shape[1:] != (2,) or len(infos) != len(achieved):
            raise ValueError(
                f"compute_reward needs (B, 2) achieved and desired goals and B infos, got {achieved.shape}, "
                f"{desired.shape} and {len(infos)} infos"
            )
        rewards = np.zeros(len(achieved))
        for i, step_info in enumerate(infos):
            if "terminal" not in step_info:
                raise ValueError(
                    "compute_reward needs each transition's step info (with 'terminal'); make "
                    "HerReplayBuffer with copy_info_dict=True"
                )
            if step_info["terminal"]:
                rewards[i] = self._terminal_reward(achieved[i], desired[i], step_info)
        return float(rewards[0]) if single else rewards

    def _terminal_reward(self, achieved: np.ndarray, desired: np.ndarray, info: dict[str, Any]) -> float:
        if info.get("unstable", False):
            return float(self.worst_reward)
        return max(-float(np.linalg.norm(achieved - desired)), float(self.worst_reward))

    def object_paths(self, trajectories: np.ndarray, goals: np.ndarray) -> tuple[np.ndarray, list[dict[str, Any]]]:
        """Play open-loop trajectories (the fast path) and return the achieved goal of every step, as the step path
        observes it, with the terminal infos: what demonstrations need to enter a ``HerReplayBuffer``.

        :param trajectories: ``(B, horizon, 7)`` actions
        :param goals: ``(B, 2)`` desired goals
        :return: ``(B, horizon + 1, 2)`` achieved goals (after reset, after each step) and one terminal info each
            (with ``"terminal": True``)
        """
        self._record_paths = True
        try:
            _, infos = self.play_trajectories(trajectories, goals, allow_outside_region=True)  # hindsight goals
        finally:
            self._record_paths = False
        paths = np.stack([info.pop("object_path") for info in infos])
        for path, info in zip(paths, infos, strict=True):
            info["terminal"] = True
            if "reached" in info:
                path[-1] = info["reached"]
        return paths, infos

    def _outcome(self, rows: np.ndarray, goal: np.ndarray) -> tuple[float, dict[str, Any]]:
        reward, info = super()._outcome(rows, goal)
        if getattr(self, "_record_paths", False):
            # The object's (x, y) at reset and after each control step: the last sensor row of each step.
            ends = np.minimum(np.arange(1, self.horizon + 1) * self.frame_skip, len(rows)) - 1
            info["object_path"] = np.concatenate([self.initial_state_object_xy()[None], rows[ends, 1:3]])
        return reward, info
