"""The base class of the arm tasks: model, data, seeding, rendering, the step path and the fast open-loop path.

Both paths run exactly the same physics steps with the same controls and reduce the same per-physics-step sensor
readings with the same task function (:meth:`ArmTaskEnv._outcome`), so a trajectory played through ``step`` and
through :meth:`ArmTaskEnv.play_trajectories` gives the same reward and info.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle
from mujoco import rollout
from sb3_genrl.envs.arm import FRAME_SKIP, JOINT_NAMES, JOINT_RANGE
from sb3_genrl.envs.control import MAX_JOINT_SPEED, is_unstable, next_command, ramp, unstable_rows


class ArmTaskEnv(gym.Env, EzPickle):
    """Common machinery of the goal-conditioned arm tasks (see :class:`HockeyEnv` and :class:`BasketballEnv`).

    Subclasses give the MJCF text, the home pose, the goal distribution and the terminal reward.
    The sensor layout every task shares: ``clock`` (1), object position (3), object velocity (3), joint
    velocities (7), then task-specific sensors.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}
    horizon: int
    settle_steps: int
    worst_reward: float
    goal_low: np.ndarray
    goal_high: np.ndarray

    def __init__(
        self,
        *,
        max_joint_delta: float = 0.5,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        **kwargs: Any,
    ) -> None:
        EzPickle.__init__(self, max_joint_delta=max_joint_delta, render_mode=render_mode, width=width, height=height, **kwargs)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        if not max_joint_delta > 0:
            raise ValueError(f"max_joint_delta must be positive, got {max_joint_delta}")
        self.model = mujoco.MjModel.from_xml_string(self._mjcf())
        self.model.vis.global_.offwidth = max(self.model.vis.global_.offwidth, width)
        self.model.vis.global_.offheight = max(self.model.vis.global_.offheight, height)
        self.data = mujoco.MjData(self.model)
        self.frame_skip = FRAME_SKIP
        self.max_joint_delta = float(max_joint_delta)
        self.render_mode = render_mode
        self.width, self.height = width, height
        self._joint_qpos = np.array([self.model.joint(n).qposadr[0] for n in JOINT_NAMES])
        self._joint_qvel = np.array([self.model.joint(n).dofadr[0] for n in JOINT_NAMES])
        self._goal_mocap = self.model.body("goal").mocapid[0]
        self._state_spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.initial_state = self._settled_initial_state()
        self.action_space = spaces.Box(-self.max_joint_delta, self.max_joint_delta, shape=(7,), dtype=np.float32)
        self.context_space = spaces.Box(self.goal_low.astype(np.float32), self.goal_high.astype(np.float32), dtype=np.float32)
        obs_low = np.concatenate([self.goal_low, JOINT_RANGE[:, 0], np.full(7, -MAX_JOINT_SPEED)]).astype(np.float32)
        obs_high = np.concatenate([self.goal_high, JOINT_RANGE[:, 1], np.full(7, MAX_JOINT_SPEED)]).astype(np.float32)
        self.observation_space = spaces.Box(obs_low, obs_high, dtype=np.float32)
        self.goal = 0.5 * (self.goal_low + self.goal_high)
        self._renderer = None
        self._reset_episode()

    # ----------------------------------------------------------------------------------------- task hooks
    def _mjcf(self) -> str:
        raise NotImplementedError

    def home_qpos(self) -> np.ndarray:
        """Joint positions (7,) of the pose every episode starts from."""
        raise NotImplementedError

    def sample_goal(self, rng: np.random.Generator) -> np.ndarray:
        raise NotImplementedError

    def _place_objects(self) -> None:
        """Put the task object where it starts, the arm being at its home pose."""
        raise NotImplementedError

    def _settled(self, row: np.ndarray) -> bool:
        """Whether the flight or slide is over, judged on one sensor row at a control step boundary."""
        return False

    def _outcome(self, rows: np.ndarray, goal: np.ndarray) -> tuple[float, dict[str, Any]]:
        """The terminal reward and summary of an episode from its sensor rows (one per physics step)."""
        raise NotImplementedError

    # ----------------------------------------------------------------------------------------- set-up
    def _settled_initial_state(self) -> np.ndarray:
        """Arm at home, holding still, object resting: simulate half a second and keep the full physics state."""
        mujoco.mj_resetData(self.model, self.data)
        home = self.home_qpos()
        self.data.qpos[self._joint_qpos] = home
        self.data.ctrl[:] = home
        self._place_objects()
        mujoco.mj_forward(self.model, self.data)
        mujoco.mj_step(self.model, self.data, nstep=250)
        self.data.time = 0.0
        state = np.empty(mujoco.mj_stateSize(self.model, self._state_spec))
        mujoco.mj_getState(self.model, self.data, state, self._state_spec)
        return state

    def _reset_episode(self) -> None:
        mujoco.mj_resetData(self.model, self.data)
        mujoco.mj_setState(self.model, self.data, self.initial_state, self._state_spec)
        self.data.ctrl[:] = self.home_qpos()
        self.data.mocap_pos[self._goal_mocap, :2] = self.goal
        mujoco.mj_forward(self.model, self.data)
        self._command = self.home_qpos().copy()
        self._t = 0
        self._rows: list[np.ndarray] = []
        self._clipped_steps = 0
        self._done = False

    # ----------------------------------------------------------------------------------------- gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        if options.get("goal") is None:
            self.goal = self.sample_goal(self.np_random)
        else:
            self.goal = self._check_goals(
                options["goal"], None, "options['goal']", allow_outside_region=bool(options.get("allow_outside_region", False))
            )
        self._reset_episode()
        return self._get_obs(), {"goal": self.goal.copy()}

    def step(self, action):
        if self._done:
            raise RuntimeError("step() called after the episode ended; call reset() first")
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (7,):
            raise ValueError(f"action must have shape (7,), got {action.shape}")
        if not np.all(np.isfinite(action)):
            raise ValueError(f"action contains non-finite values: {action}")
        previous = self._command
        command, clipped = next_command(self._command[None], action[None], self.max_joint_delta)
        self._command = command[0]
        self._clipped_steps += int(clipped[0])
        unstable = self._simulate(ramp(previous[None], self._command[None], self.frame_skip)[0])
        self._t += 1
        if not unstable and self._t == self.horizon:
            hold = np.repeat(self._command[None], self.frame_skip, axis=0)
            for _ in range(self.settle_steps):
                if self._settled(self._rows[-1]):
                    break
                if self._simulate(hold):
                    break
        terminated = unstable or self._t == self.horizon
        reward, info = 0.0, {}
        if terminated:
            reward, info = self._finish(np.asarray(self._rows), self.goal, self._clipped_steps)
            self._done = True
        return self._get_obs(), reward, terminated, False, info

    def _simulate(self, targets: np.ndarray) -> bool:
        """Step the physics once per row of ``targets`` (commanded joint positions), recording each sensor row;
        True when the simulation went unstable."""
        first = max(len(self._rows) - 1, 0)  # the row before these steps: the clock must advance from it
        for target in targets:
            self.data.ctrl[:] = target
            mujoco.mj_step(self.model, self.data)
            self._rows.append(self.data.sensordata.copy())
        # Checked once per control step, not per physics step (the check costs twice the physics). The rows after a
        # divergence within this control step change nothing: ``_finish`` reads only the rows before the first bad
        # one, as for a rollout (:meth:`_episode_length`).
        return is_unstable(np.asarray(self._rows[first:]))

    def _finish(self, rows: np.ndarray, goal: np.ndarray, clipped_steps: int) -> tuple[float, dict[str, Any]]:
        info: dict[str, Any] = {"joint_limit_clipped": clipped_steps > 0, "clipped_steps": clipped_steps}
        bad = unstable_rows(rows)
        if bad.any():
            first_bad = int(np.argmax(bad))
            if first_bad > 0:  # what happened before the simulation diverged (contacts, object position)
                info.update(self._outcome(rows[:first_bad], goal)[1])
            info.update(unstable=True, reward=self.worst_reward)
            return self.worst_reward, info
        reward, summary = self._outcome(rows, goal)
        reward = max(reward, self.worst_reward)
        info.update(summary, unstable=False, reward=reward)
        return reward, info

    def _get_obs(self) -> np.ndarray:
        qpos = np.clip(self.data.qpos[self._joint_qpos], JOINT_RANGE[:, 0], JOINT_RANGE[:, 1])
        qvel = np.clip(self.data.qvel[self._joint_qvel], -MAX_JOINT_SPEED, MAX_JOINT_SPEED)
        return np.concatenate([self.goal, qpos, qvel]).astype(np.float32)

    def initial_state_object_xy(self) -> np.ndarray:
        """Where the task object (puck or ball) rests at the start of every episode, (x, y) in metres."""
        data = mujoco.MjData(self.model)
        mujoco.mj_setState(self.model, data, self.initial_state, self._state_spec)
        mujoco.mj_forward(self.model, data)
        return data.sensordata[1:3].copy()

    def get_context(self) -> np.ndarray:
        """The task context of the current episode: the goal's (x, y) in metres."""
        return self.goal.astype(np.float32)

    def hindsight(self, info: dict[str, Any]) -> tuple[np.ndarray, float] | None:
        """The goal an episode with this terminal ``info`` solved, and its reward there: the point it reached
        (``info["reached"]``) and 0, its distance to itself; ``None`` when the simulation was unstable. The context
        that GenRL's hindsight relabelling (``hindsight_kwargs``) gives the episode (see
        :class:`~sb3_genrl.LatentActionWrapper`)."""
        if info.get("unstable", False) or "reached" not in info:
            return None
        return np.asarray(info["reached"], dtype=np.float32), 0.0

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
        self._renderer.update_scene(self.data, camera="overview")
        return self._renderer.render().copy()

    def close(self) -> None:
        self._close_pool()
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def episode_frames(self, trajectory: np.ndarray, goal: np.ndarray, *, every: int = 1) -> list[np.ndarray]:
        """Play ``trajectory`` for ``goal`` like the step path and return ``rgb_array`` frames (every ``every`` control
        steps, the settle phase included). Needs ``render_mode="rgb_array"``."""
        if self.render_mode != "rgb_array":
            raise ValueError("episode_frames needs an env made with render_mode='rgb_array'")
        trajectory = self._check_trajectories(trajectory)[0]
        self.reset(options={"goal": goal})
        frames = [self.render()]
        for t, action in enumerate(trajectory):
            previous = self._command
            self._command = next_command(self._command[None], action[None], self.max_joint_delta)[0][0]
            if self._simulate(ramp(previous[None], self._command[None], self.frame_skip)[0]):
                break
            if (t + 1) % every == 0:
                frames.append(self.render())
        hold = np.repeat(self._command[None], self.frame_skip, axis=0)
        for t in range(self.settle_steps):
            if self._settled(self._rows[-1]) or self._simulate(hold):
                break
            if (t + 1) % every == 0:
                frames.append(self.render())
        self._done = True
        return frames

    def _check_goals(
        self, goals: np.ndarray, n: int | None, name: str = "goals", *, allow_outside_region: bool = False
    ) -> np.ndarray:
        """Goals as finite float64 ``(x, y)`` pairs inside the goal region, or a ``ValueError`` naming the problem.

        :param goals: one ``(2,)`` goal, or ``(n, 2)`` goals
        :param n: ``None`` for one ``(2,)`` goal; else the number of goals needed (one ``(2,)`` goal is repeated)
        :param name: how the error message calls ``goals``
        :param allow_outside_region: accept goals outside the region (hindsight goals: points demonstrations reached)
        :return: a ``(2,)`` array when ``n`` is ``None``, else ``(n, 2)``
        """
        goals = np.array(goals, dtype=np.float64)
        if goals.shape != (2,) and (n is None or goals.shape != (n, 2)):
            expected = "(2,)" if n is None else f"(2,) or ({n}, 2)"
            raise ValueError(f"{name} must have shape {expected} (x, y in metres), got shape {goals.shape}")
        if not np.all(np.isfinite(goals)):
            raise ValueError(f"{name} contains non-finite values (nan or inf): {goals}")
        if not allow_outside_region:
            # The region's float32 bounds (the context space's) count too, so that goals passed as float32 pass.
            low = np.minimum(self.goal_low, self.goal_low.astype(np.float32))
            high = np.maximum(self.goal_high, self.goal_high.astype(np.float32))
            outside = np.any((goals < low) | (goals > high), axis=-1) | ~self._in_region(goals.reshape(-1, 2)).reshape(
                goals.shape[:-1]
            )
            if np.any(outside):
                raise ValueError(
                    f"{name} {goals[outside] if goals.ndim == 2 else goals} lies outside the goal region "
                    f"({self.goal_region_text(low, high)}) of {type(self).__name__}"
                )
        return goals if n is None else np.broadcast_to(goals, (n, 2))

    def _in_region(self, goals: np.ndarray) -> np.ndarray:
        """Per goal ``(N, 2)``: whether it lies in the region beyond its bounding box (a task whose region is not a
        box overrides this; the bounding box itself is checked by :meth:`_check_goals`)."""
        return np.ones(len(goals), dtype=bool)

    def goal_region_text(self, low: np.ndarray, high: np.ndarray) -> str:
        """The goal region in words, for error messages."""
        return f"x in [{low[0]}, {high[0]}], y in [{low[1]}, {high[1]}]"

    def _check_trajectories(self, trajectories: np.ndarray) -> np.ndarray:
        trajectories = np.asarray(trajectories, dtype=np.float64)
        if trajectories.ndim == 2:
            trajectories = trajectories[None]
        if trajectories.ndim != 3 or trajectories.shape[1:] != (self.horizon, 7):
            raise ValueError(f"trajectories must have shape (B, {self.horizon}, 7), got {trajectories.shape}")
        if not np.all(np.isfinite(trajectories)):
            raise ValueError("trajectories contain non-finite values (nan or inf)")
        return trajectories

    # ----------------------------------------------------------------------------------------- fast path
    def play_trajectory(
        self, trajectory: np.ndarray, goal: np.ndarray, *, allow_outside_region: bool = False
    ) -> tuple[float, dict[str, Any]]:
        """Play one ``(horizon, 7)`` trajectory for ``goal``; the same reward and info as stepping through it."""
        rewards, infos = self.play_trajectories(
            np.asarray(trajectory)[None], np.asarray(goal)[None], allow_outside_region=allow_outside_region
        )
        return float(rewards[0]), infos[0]

    def play_trajectories(
        self,
        trajectories: np.ndarray,
        goals: np.ndarray,
        *,
        n_threads: int = 1,
        chunk: int = 256,
        return_joint_states: bool = False,
        allow_outside_region: bool = False,
    ) -> tuple[np.ndarray, list[dict[str, Any]]] | tuple[np.ndarray, list[dict[str, Any]], np.ndarray]:
        """Play a batch of open-loop trajectories with :mod:`mujoco.rollout` (no per-step Python).

        :param trajectories: ``(B, horizon, 7)`` joint position deltas in radians (one trajectory may be ``(horizon, 7)``)
        :param goals: ``(B, 2)`` goal positions in metres (or one ``(2,)`` goal for all)
        :param n_threads: simulation threads; ``mujoco.rollout`` splits the batch between them
        :param chunk: trajectories simulated per call, bounding memory (each keeps every physics step's sensors)
        :param return_joint_states: also return the joint part of the step env's observations, ``(B, horizon + 1,
            14)`` float32 (positions then velocities at each control step boundary, the last after the settle phase)
        :param allow_outside_region: accept goals outside the goal region (hindsight goals); refused by default
        :return: rewards ``(B,)`` and one info dict per trajectory (and the joint states when asked)
        """
        trajectories = self._check_trajectories(trajectories)
        goals = self._check_goals(goals, len(trajectories), allow_outside_region=allow_outside_region)
        for name, value in (("n_threads", n_threads), ("chunk", chunk)):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        datas, pool = self._rollout_pool(n_threads)
        rewards = np.empty(len(trajectories))
        infos: list[dict[str, Any]] = []
        joint_states = np.empty((len(trajectories), self.horizon + 1, 14), np.float32) if return_joint_states else None
        for start in range(0, len(trajectories), chunk):
            batch = trajectories[start : start + chunk]
            commands = np.empty_like(batch)
            command = np.tile(self.home_qpos(), (len(batch), 1))
            clipped = np.zeros(len(batch), dtype=int)
            for t in range(self.horizon):
                command, clip_t = next_command(command, batch[:, t], self.max_joint_delta)
                commands[:, t] = command
                clipped += clip_t
            previous = np.concatenate([np.tile(self.home_qpos(), (len(batch), 1, 1)), commands[:, :-1]], axis=1)
            controls = ramp(previous, commands, self.frame_skip).reshape(len(batch), -1, 7)
            hold = np.repeat(commands[:, -1:], self.settle_steps * self.frame_skip, axis=1)
            controls = np.concatenate([controls, hold], axis=1)
            states, sensordata = pool.rollout(
                self.model, datas, self.initial_state[None], controls, initial_warmstart=np.zeros((1, self.model.nv))
            )
            for i, rows in enumerate(sensordata):
                length = self._episode_length(rows)
                reward, info = self._finish(rows[:length], goals[start + i], int(clipped[i]))
                rewards[start + i] = reward
                infos.append(info)
                if joint_states is not None:
                    joint_states[start + i] = self._joint_states(states[i], length)
        if joint_states is not None:
            return rewards, infos, joint_states
        return rewards, infos

    def _rollout_pool(self, n_threads: int) -> tuple[list[mujoco.MjData], rollout.Rollout]:
        """One ``MjData`` per thread and ``mujoco.rollout``'s thread pool, kept between calls: making them anew costs
        milliseconds per call, as much as a short batch's physics (batched GenRL plays a batch every step)."""
        if getattr(self, "_pool", None) is None or self._pool[0] != n_threads:
            self._close_pool()
            self._pool = (
                n_threads,
                [mujoco.MjData(self.model) for _ in range(n_threads)],
                rollout.Rollout(nthread=n_threads if n_threads > 1 else 0),
            )
        return self._pool[1], self._pool[2]

    def _close_pool(self) -> None:
        if getattr(self, "_pool", None) is not None:
            self._pool[2].close()
            self._pool = None

    def _joint_states(self, states: np.ndarray, length: int) -> np.ndarray:
        """Joint positions and velocities (as :meth:`_get_obs` clips them) after each control step of a rollout."""
        steps = np.minimum(np.arange(1, self.horizon + 1) * self.frame_skip, length) - 1
        steps[-1] = length - 1
        rows = np.concatenate([self.initial_state[None], states[steps]])
        qpos = np.clip(rows[:, 1 + self._joint_qpos], JOINT_RANGE[:, 0], JOINT_RANGE[:, 1])
        qvel = np.clip(rows[:, 1 + self.model.nq + self._joint_qvel], -MAX_JOINT_SPEED, MAX_JOINT_SPEED)
        return np.concatenate([qpos, qvel], axis=1)

    def _episode_length(self, rows: np.ndarray) -> int:
        """Number of physics steps the step path runs for these rows: it stops at instability or when settled."""
        bad = unstable_rows(rows)
        if bad.any():
            return int(np.argmax(bad)) + 1
        end = self.horizon * self.frame_skip
        for _ in range(self.settle_steps):
            if self._settled(rows[end - 1]):
                break
            end += self.frame_skip
        return end
