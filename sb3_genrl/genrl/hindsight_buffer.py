"""GenRL's hindsight rollout buffer: SB3's rollout buffer that also stores, with each pull, what hindsight needs.

GenRL's ``hindsight_kwargs`` puts :class:`HindsightRolloutBuffer` in SB3's ``rollout_buffer_class`` slot, as SB3's HER is
its ``HerReplayBuffer`` given as ``replay_buffer_class``. Besides what SB3's buffer keeps, ``add`` stores each pull's
relabelling: the context it solved and the reward it earns there, from ``info["hindsight"] = (context', r')``
(:class:`~sb3_genrl.LatentActionWrapper` reports it), with the latent action played and, for the refits of
:mod:`sb3_genrl.genrl.refits`, whether the pull solved its own context (``info["is_success"]``). Each is kept in the row
of the pull it belongs to, so :meth:`HindsightRolloutBuffer.relabelled_pulls` and
:meth:`HindsightRolloutBuffer.solving_pulls` read them without working out where ``get()`` put a pull.

How the infos reach ``add``: SB3's off-policy loop gives a step's infos to the replay buffer's ``add`` (which is how
HER gets them); its on-policy loop, ``OnPolicyAlgorithm.collect_rollouts``, calls
``rollout_buffer.add(obs, actions, rewards, episode_starts, values, log_probs)`` without them. The public place where
an on-policy step's infos are seen is a callback: ``collect_rollouts`` calls ``callback.on_step()`` after ``env.step``
and before ``rollout_buffer.add``, with the step's ``infos`` and the ``rollout_buffer`` among the callback's ``locals``.
So :class:`PullInfosCallback`, which :meth:`GenRL.learn <sb3_genrl.GenRL.learn>` puts first among the callbacks when
its buffer is a :class:`HindsightRolloutBuffer`, hands each step's infos to :meth:`HindsightRolloutBuffer.add_infos`;
they are checked there (a pull that cannot be relabelled, or a relabelled reward that is not one finite number, is
refused at the first pull) and stored by the next ``add``. No private method of SB3 is overridden.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback

from sb3_genrl.genrl.buffers import FiniteRewardRolloutBuffer

NO_HINDSIGHT_INFO = (
    "hindsight_kwargs needs every pull's info['hindsight']: (context, reward) or None. "
    "LatentActionWrapper reports it when the task defines hindsight(info) and the context is the task's "
    "get_context(), and for any goal-conditioned env (a Dict observation with observation, achieved_goal "
    "and desired_goal, and compute_reward); this env's info has no such key (history: 0 relabels no pull, for "
    "the refits alone)"
)
NO_SUCCESS_INFO = (
    "hindsight_kwargs['refit_every'] refits the policy's mean to the pulls that solved their own context, "
    "which needs every pull's info['is_success'] (the goal-conditioned envs report it); this env's info "
    "has no such key: name the key that holds its success (train_policy's success_key, --success-key), or "
    "leave the refits out (hindsight_kwargs without refit_every, success_kl_floor None; --genrl-kwargs "
    '\'{"hindsight_kwargs": null, "success_kl_floor": null}\')'
)


def check_relabelled_reward(hindsight: Any) -> None:
    """Refuse an ``info["hindsight"]`` that is not ``(context, reward)`` with one finite reward."""
    if not isinstance(hindsight, tuple | list) or len(hindsight) != 2:
        raise ValueError(f"info['hindsight'] must be (context, reward) or None, got {hindsight!r}")
    reward = np.asarray(hindsight[1])
    if reward.size != 1 or not np.issubdtype(reward.dtype, np.number) or not np.isfinite(reward.item()):
        raise ValueError(
            f"info['hindsight'] holds the relabelled reward {hindsight[1]!r}, not one finite number (from the task's "
            "hindsight(info), or a goal-conditioned env's compute_reward): a relabelled pull's reward must be one "
            "finite number"
        )


class HindsightRolloutBuffer(FiniteRewardRolloutBuffer):
    """SB3's rollout buffer (refusing a non-finite reward) that stores each pull's relabelling (see the module doc).

    A pull is relabelled when its ``info["hindsight"]`` is not ``None`` and its context' is finite and inside the
    observation box; the others are left out of :meth:`relabelled_pulls`.

    :param buffer_size: steps per env of a rollout (GenRL's ``n_steps``)
    :param observation_space: the context space (a ``Box``)
    :param action_space: the latent action space
    :param device: torch device of the tensors it returns
    :param gae_lambda: as SB3's ``RolloutBuffer`` (GenRL: 1)
    :param gamma: as SB3's ``RolloutBuffer`` (GenRL: 1)
    :param n_envs: envs of the VecEnv
    :param success: also store whether each pull solved its own context, ``info["is_success"]`` (default False)
    :param relabel: store each pull's relabelling, ``info["hindsight"]`` (default True; False: ``hindsight_kwargs``'s
        ``history: 0``, where no pull is relabelled and the env need not report it)
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        gae_lambda: float = 1,
        gamma: float = 0.99,
        n_envs: int = 1,
        *,
        success: bool = False,
        relabel: bool = True,
    ) -> None:
        if not isinstance(observation_space, spaces.Box):
            raise ValueError(f"hindsight_kwargs relabels Box contexts; this env's context space is {observation_space}")
        self.success, self.relabel = bool(success), bool(relabel)
        self.infos: list[dict[str, Any]] | None = None  # the infos of the step the next add() stores
        super().__init__(buffer_size, observation_space, action_space, device, gae_lambda, gamma, n_envs)

    def reset(self) -> None:
        rows = (self.buffer_size, self.n_envs)
        self.pull_contexts = np.zeros((*rows, *self.obs_shape), dtype=np.float32)  # as played (SB3 stores float32)
        self.pull_actions = np.zeros((*rows, self.action_dim), dtype=np.float32)
        self.relabelled = np.zeros(rows, dtype=bool)
        self.relabelled_contexts = np.zeros((*rows, *self.obs_shape), dtype=self.observation_space.dtype)
        self.relabelled_rewards = np.zeros(rows, dtype=np.float32)
        self.successes = np.zeros(rows, dtype=bool)
        self.infos = None
        super().reset()

    def add_infos(self, infos: list[dict[str, Any]]) -> None:
        """Hold one step's infos (one per env) for the next :meth:`add`; refused at once (``relabel``) when a pull
        cannot be relabelled or a relabelled reward is not one finite number, or (``success``) when a pull has no
        ``info["is_success"]``."""
        if len(infos) != self.n_envs:
            raise ValueError(f"add_infos: {len(infos)} infos for a step of {self.n_envs} envs")
        if self.relabel and not all("hindsight" in info for info in infos):
            raise ValueError(NO_HINDSIGHT_INFO)
        if self.success and not all("is_success" in info for info in infos):
            raise ValueError(NO_SUCCESS_INFO)
        for info in infos:
            if self.relabel and info["hindsight"] is not None:
                check_relabelled_reward(info["hindsight"])
        self.infos = list(infos)

    def add(
        self,
        obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        episode_start: np.ndarray,
        value: th.Tensor,
        log_prob: th.Tensor,
    ) -> None:
        """SB3's ``add``, storing with the step's pulls their relabelling, from the infos :meth:`add_infos` held."""
        infos, self.infos = self.infos, None
        if infos is None:
            raise RuntimeError(
                "HindsightRolloutBuffer.add: no infos for this step; GenRL.learn hands them over with its "
                "PullInfosCallback, a rollout collected otherwise must call add_infos(infos) before each add"
            )
        row, space = self.pos, self.observation_space
        self.pull_contexts[row] = np.array(obs)
        self.pull_actions[row] = np.array(action).reshape((self.n_envs, self.action_dim))
        for env_index, info in enumerate(infos):
            self.successes[row, env_index] = self.success and bool(info["is_success"])
            if not self.relabel or info["hindsight"] is None:
                continue
            context, relabelled_reward = info["hindsight"]
            context = np.asarray(context, dtype=space.dtype).reshape(space.shape)
            if np.all(np.isfinite(context)) and np.all(context >= space.low) and np.all(context <= space.high):
                self.relabelled[row, env_index] = True
                self.relabelled_contexts[row, env_index] = context
                self.relabelled_rewards[row, env_index] = float(relabelled_reward)
        super().add(obs, action, reward, episode_start, value, log_prob)

    def relabelled_pulls(self) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """The rollout's relabelled pulls, step by step (the envs of a step in order): contexts', latent actions as
        played, rewards'."""
        rows = self.relabelled
        return (
            th.as_tensor(self.relabelled_contexts[rows], device=self.device),
            th.as_tensor(self.pull_actions[rows], device=self.device),
            th.as_tensor(self.relabelled_rewards[rows], device=self.device),
        )

    def solving_pulls(self) -> tuple[th.Tensor, th.Tensor]:
        """The rollout's pulls that solved their own context, step by step: contexts, and latent actions as played,
        clipped to the action space."""
        if not self.success:
            raise RuntimeError("HindsightRolloutBuffer(success=False) does not store whether a pull solved its context")
        rows, space = self.successes, self.action_space
        actions = np.clip(self.pull_actions[rows], space.low, space.high).astype(np.float32)  # type: ignore[attr-defined]
        return th.as_tensor(self.pull_contexts[rows], device=self.device).float(), th.as_tensor(actions, device=self.device)


class PullInfosCallback(BaseCallback):
    """Hand each step's infos to the rollout buffer being filled (:meth:`HindsightRolloutBuffer.add_infos`), before
    ``collect_rollouts`` adds the step's pulls to it (see the module doc)."""

    def _on_step(self) -> bool:
        self.locals["rollout_buffer"].add_infos(self.locals["infos"])
        return True
