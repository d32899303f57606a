"""Hindsight relabelling for GenRL: each pull joins the E-step a second time, relabelled with the context it solved.

The latent-space counterpart of hindsight experience replay (Andrychowicz et al., 2017), switched on by GenRL's
``hindsight_kwargs`` as SB3 switches on its ``HerReplayBuffer`` with ``replay_buffer_kwargs``. A pull whose info holds
``info["hindsight"] = (context', r')`` (the context for which its trajectory earns the best reward, and that reward;
:class:`~sb3_genrl.LatentActionWrapper` asks the task's ``hindsight(info)`` for it, or derives it from a goal-conditioned
env's own API: the last achieved goal as desired goal, the reward by ``compute_reward``) is treated as if
``pi(.|context')`` had drawn it: its ratio ``q/pi`` is taken at ``context'`` and its advantage is ``r' - V(context')``,
so it stays inside the E-step's KL bound. Relabelled pulls remain true after the policy has moved on (the trajectory
of ``alpha`` still reaches ``context'``), so those of the last ``history`` batches are kept and reweighed with the
current policy and value function at every iteration. Optionally the policy's mean is also fitted to the kept pulls
(:mod:`sb3_genrl.genrl.regression`), or refitted now and then to the run's own solving pulls
(:meth:`HindsightRelabelling.refit`). Under the KL-penalty E-step the ratio of a pull that ``pi`` makes unlikely at
its new context grows faster than the penalty, so relabelling needs the TRPO E-step.
"""

from __future__ import annotations

import collections
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.policies import ActorCriticPolicy

from sb3_genrl.genrl.regression import fit_mean, mean_parameters, regress_mean
from sb3_genrl.genrl.value import use_foreach

Batch = tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor]  # observations, actions, log pi(actions), advantages
DEFAULTS: dict[str, Any] = {
    "history": 1,
    "regression_steps": 0,
    "regression_lr": 1e-3,
    "regression_batch_size": 256,
    "regression_weighted": False,
    "refit_every": 0,
    "refit_start": None,
    "refit_steps": 4000,
}
NO_HINDSIGHT_INFO = (
    "hindsight_kwargs needs every pull's info['hindsight']: (context, reward) or None. "
    "LatentActionWrapper reports it when the task defines hindsight(info) and the context is the task's "
    "get_context(), and for any goal-conditioned env (a Dict observation with observation, achieved_goal "
    "and desired_goal, and compute_reward); this env's info has no such key"
)
NO_SUCCESS_INFO = (
    "hindsight_kwargs['refit_every'] refits the policy's mean to the pulls that solved their own context, "
    "which needs every pull's info['is_success'] (the goal-conditioned envs report it); this env's info "
    "has no such key"
)


def check_hindsight_kwargs(hindsight_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """Refuse hindsight settings that :class:`HindsightRelabelling` would not take, naming the setting.

    :param hindsight_kwargs: some of ``history``, ``regression_steps``, ``regression_lr``, ``regression_batch_size``,
        ``regression_weighted``, ``refit_every``, ``refit_start``, ``refit_steps``
    :return: a plain dict copy
    """
    if not isinstance(hindsight_kwargs, Mapping):
        raise ValueError(f"hindsight_kwargs must be a dict or None, got {hindsight_kwargs!r}")
    unknown = sorted(set(hindsight_kwargs) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"hindsight_kwargs: {', '.join(map(repr, unknown))} not among its settings ({', '.join(DEFAULTS)})")
    settings = DEFAULTS | dict(hindsight_kwargs)
    for key, minimum in (
        ("history", 1),
        ("regression_steps", 0),
        ("regression_batch_size", 1),
        ("refit_every", 0),
        ("refit_steps", 1),
    ):
        value = settings[key]
        if isinstance(value, bool) or int(value) != value or value < minimum:
            raise ValueError(f"hindsight_kwargs['{key}'] must be an integer >= {minimum}, got {value!r}")
    start = settings["refit_start"]
    if start is not None and (isinstance(start, bool) or int(start) != start or start < 1):
        raise ValueError(f"hindsight_kwargs['refit_start'] must be an integer >= 1 or None, got {start!r}")
    if start is not None and not settings["refit_every"]:
        raise ValueError("hindsight_kwargs['refit_start'] is the episode of the first refit, which needs refit_every > 0")
    if not settings["regression_lr"] > 0:
        raise ValueError(f"hindsight_kwargs['regression_lr'] must be positive, got {settings['regression_lr']!r}")
    if not isinstance(settings["regression_weighted"], bool | np.bool_):
        raise ValueError(
            f"hindsight_kwargs['regression_weighted'] must be True or False, got {settings['regression_weighted']!r}"
        )
    if settings["regression_weighted"] and not settings["regression_steps"]:
        raise ValueError(
            "hindsight_kwargs['regression_weighted'] weights the regression's pulls, which needs regression_steps > 0"
        )
    return dict(hindsight_kwargs)


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


class HindsightRelabelling:
    """The relabelled pulls of GenRL's last batches, and the fit of the policy's mean to them (see the module doc).

    :param policy: the policy (a Box context); its current distribution and value function weigh the kept pulls
    :param history: batches whose relabelled pulls join the E-step: the current one and those before it (default 1)
    :param regression_steps: Adam steps per iteration fitting the policy's mean to the kept pulls (default 0: none)
    :param regression_lr: Adam learning rate of that fit (default 1e-3)
    :param regression_batch_size: pulls per step of the fit, drawn with replacement from the kept ones (default 256)
    :param regression_weighted: weight each pull's error by the policy's density at it relative to its mode
        (default False; see :func:`~sb3_genrl.genrl.regression.regress_mean`)
    :param refit_every: episodes between refits of the policy's mean to the run's solving pulls (default 0: none;
        see :meth:`refit`)
    :param refit_start: the episode of the first refit (default None: ``refit_every``)
    :param refit_steps: Adam steps of each refit (default 4000), with ``regression_lr`` and ``regression_batch_size``
    """

    def __init__(
        self,
        policy: ActorCriticPolicy,
        *,
        history: int = 1,
        regression_steps: int = 0,
        regression_lr: float = 1e-3,
        regression_batch_size: int = 256,
        regression_weighted: bool = False,
        refit_every: int = 0,
        refit_start: int | None = None,
        refit_steps: int = 4000,
    ) -> None:
        check_hindsight_kwargs(
            {
                "history": history,
                "regression_steps": regression_steps,
                "regression_lr": regression_lr,
                "regression_batch_size": regression_batch_size,
                "regression_weighted": regression_weighted,
                "refit_every": refit_every,
                "refit_start": refit_start,
                "refit_steps": refit_steps,
            }
        )
        if not isinstance(policy.observation_space, spaces.Box):
            raise ValueError(f"hindsight_kwargs relabels Box contexts; this env's context space is {policy.observation_space}")
        self.policy, self.history = policy, int(history)
        self.regression_steps, self.regression_lr = int(regression_steps), regression_lr
        self.regression_batch_size, self.regression_weighted = int(regression_batch_size), bool(regression_weighted)
        self.pull_infos: list[list[dict[str, Any]]] = []  # the infos of the rollout's pulls, step by step
        # (contexts, latent actions, rewards) relabelled in the last `history` batches
        self.memory: collections.deque[tuple[th.Tensor, th.Tensor, th.Tensor]] = collections.deque(maxlen=self.history)
        self.kept_pulls: tuple[th.Tensor, th.Tensor, th.Tensor] | None = None  # kept for the whole run (keep_pulls)
        # Adam over the policy's mean; it keeps its moments from iteration to iteration (and is saved with the model)
        self.optimizer = th.optim.Adam(mean_parameters(policy), lr=regression_lr) if self.regression_steps else None
        self.refit_every, self.refit_steps = int(refit_every), int(refit_steps)
        self.refit_start = self.refit_every if refit_start is None else int(refit_start)
        # (contexts, latent actions) of the pulls that solved their own context, one entry per batch, for the whole run
        self.solved: list[tuple[th.Tensor, th.Tensor]] = []
        # the weights of the policy's mean as it was made, from which every refit starts (None without refits)
        self.initial_mean = [parameter.detach().clone() for parameter in mean_parameters(policy)] if self.refit_every else None

    def reset(self) -> None:
        """Forget the pull infos of the rollout before (a rollout starts)."""
        self.pull_infos = []

    def add_infos(self, infos: list[dict[str, Any]]) -> None:
        """Keep one step's infos of the rollout (one per env); refused at once when they cannot be relabelled, or when
        a relabelled pull's reward is not one finite number (where the relabelled rewards enter GenRL)."""
        if not all("hindsight" in info for info in infos):
            raise ValueError(NO_HINDSIGHT_INFO)
        if self.refit_every and not all("is_success" in info for info in infos):
            raise ValueError(NO_SUCCESS_INFO)
        for info in infos:
            if info["hindsight"] is not None:
                check_relabelled_reward(info["hindsight"])
        self.pull_infos.append(infos)

    def extend_batch(
        self, batch: Batch, rollout_buffer: RolloutBuffer, advantage_mean: th.Tensor | float, advantage_std: th.Tensor | float
    ) -> tuple[Batch, float]:
        """The E-step's batch with the relabelled pulls of this rollout and of the ``history - 1`` before it joined.

        Each joins as (context', latent action, log-probability under the current policy at context',
        ``(r' - V(context') - advantage_mean) / advantage_std``). Relabelled contexts outside the observation box,
        and pulls whose info holds ``None``, are left out.

        :param batch: the rollout's pulls as played (observations, actions, log-probabilities, advantages)
        :param rollout_buffer: the rollout buffer that holds them (after ``get()``)
        :return: the joined batch, and the relabelled pulls per pull played
        """
        self.memory.append(self._relabel(rollout_buffer))
        contexts, actions, rewards = self._kept()
        with th.no_grad():  # the current policy and value function, also for the pulls of earlier batches
            log_prob = self.policy.get_distribution(contexts).log_prob(actions)
            values = self.policy.predict_values(contexts).flatten()
        advantages = (rewards.to(values.dtype) - values - advantage_mean) / advantage_std
        relabelled = (contexts, actions, log_prob, advantages)
        joined = tuple(th.cat([played, extra]) for played, extra in zip(batch, relabelled, strict=True))
        return joined, len(contexts) / len(batch[0])  # type: ignore[return-value]

    def regress(self) -> list[float]:
        """Fit the policy's mean to the kept relabelled pulls (``regression_steps`` Adam steps); the minibatch losses
        (none without the regression or without kept pulls)."""
        if not self.regression_steps or not self.memory:
            return []
        contexts, actions, _ = self._kept()
        if not len(contexts):
            return []
        use_foreach(self.optimizer)  # type: ignore[arg-type]
        return regress_mean(
            self.policy,
            self.optimizer,
            contexts,
            actions,
            steps=self.regression_steps,  # type: ignore[arg-type]
            batch_size=self.regression_batch_size,
            weighted=self.regression_weighted,
        )

    def refit(self, rollout_buffer: RolloutBuffer, episodes: int) -> dict[str, float]:
        """Keep this rollout's pulls that solved their own context (``info["is_success"]``); when the run's episode
        count ``episodes`` has just reached ``refit_start``, or ``refit_start`` plus a multiple of ``refit_every``,
        refit the policy's mean to all those kept so far: from its initial weights, by ``refit_steps`` steps of a new
        Adam, as the demonstrations are fitted.

        Each solving pull is an exact (context, latent action) pair of the map the mean should learn, as a
        demonstration is. Fitted from its initial weights rather than moved a few steps from where it is, the mean
        becomes the regression of what the run has found so far, without what earlier fits put in it (a fit
        continued for long over-fits; :mod:`sb3_genrl.genrl.demonstrations`); between refits the E-step searches
        around it. The latent actions are those played, clipped to the action space.

        :param rollout_buffer: the rollout's buffer (after ``get()``)
        :param episodes: the episodes played so far, this rollout's among them
        :return: ``refit_pairs`` and ``refit_loss`` (the mean of the last 100 minibatches') when it refitted, else {}
        """
        if not self.refit_every:
            return {}
        self.solved.append(self._solving_pulls(rollout_buffer))
        played = rollout_buffer.buffer_size * rollout_buffer.n_envs
        if self._refits_due(episodes) == self._refits_due(episodes - played):
            return {}
        contexts, actions = (th.cat(part) for part in zip(*self.solved, strict=True))
        if not len(actions):
            return {"refit_pairs": 0.0}
        with th.no_grad():
            for parameter, initial in zip(mean_parameters(self.policy), self.initial_mean, strict=True):  # type: ignore[arg-type]
                parameter.copy_(initial)
        losses = fit_mean(
            self.policy,
            contexts,
            actions,
            steps=self.refit_steps,
            learning_rate=self.regression_lr,
            batch_size=self.regression_batch_size,
        )
        return {"refit_pairs": float(len(actions)), "refit_loss": float(np.mean(losses[-100:]))}

    def _refits_due(self, episodes: int) -> int:
        """How many refits a run of ``episodes`` episodes has made (at ``refit_start``, then every ``refit_every``)."""
        return 0 if episodes < self.refit_start else (episodes - self.refit_start) // self.refit_every + 1

    def set_learning_rate(self) -> None:
        """Give the regression's Adam this component's ``regression_lr`` (after loading a saved optimizer state)."""
        for group in self.optimizer.param_groups if self.optimizer is not None else ():
            group["lr"] = self.regression_lr

    def keep_pulls(self, contexts: th.Tensor, actions: th.Tensor, rewards: th.Tensor) -> None:
        """Keep these pulls (contexts, latent actions, rewards; demonstrations, :mod:`sb3_genrl.genrl.demonstrations`)
        for the whole run: after the last ``history`` batches' relabelled pulls, in every E-step's batch and every
        regression, never aged out. They are saved in the run's checkpoints (not in the model's zip)."""
        space, n = self.policy.observation_space, len(rewards)
        shapes = (tuple(contexts.shape), tuple(actions.shape), tuple(rewards.shape))
        if shapes != ((n, *space.shape), (n, *self.policy.action_space.shape), (n,)):
            raise ValueError(
                f"keep_pulls: contexts, actions and rewards of shapes {shapes}, expected "
                f"(n, *{space.shape}), (n, *{self.policy.action_space.shape}) and (n,)"
            )
        device = self.policy.device
        self.kept_pulls = (contexts.to(device, th.float32), actions.to(device, th.float32), rewards.to(device, th.float32))

    def _kept(self) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """The kept relabelled pulls, oldest batch first, then those kept for the whole run: contexts, latent actions,
        rewards."""
        batches = [*self.memory, *([] if self.kept_pulls is None else [self.kept_pulls])]
        return tuple(th.cat(part) for part in zip(*batches, strict=True))  # type: ignore[return-value]

    def _check_rollout(self, buffer: RolloutBuffer) -> None:
        """Refuse a buffer whose rollout the kept infos are not of (or one ``get()`` has not flattened yet)."""
        if len(self.pull_infos) != buffer.buffer_size or not buffer.generator_ready:
            raise RuntimeError(f"hindsight: {len(self.pull_infos)} steps of infos for a rollout of {buffer.buffer_size}")

    def _solving_pulls(self, buffer: RolloutBuffer) -> tuple[th.Tensor, th.Tensor]:
        """This rollout's pulls that solved their own context: contexts and latent actions as played (clipped)."""
        self._check_rollout(buffer)
        rows = [
            env_index * buffer.buffer_size + step
            for step, infos in enumerate(self.pull_infos)
            for env_index, info in enumerate(infos)
            if info["is_success"]
        ]  # as get() flattened the buffer
        space, device = self.policy.action_space, self.policy.device
        actions = np.clip(buffer.actions[rows], space.low, space.high).astype(np.float32)  # type: ignore[attr-defined]
        return (th.as_tensor(buffer.observations[rows], device=device).float(), th.as_tensor(actions, device=device))

    def _relabel(self, buffer: RolloutBuffer) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """This rollout's relabelled pulls: contexts, latent actions, rewards."""
        space, device = self.policy.observation_space, self.policy.device
        self._check_rollout(buffer)
        contexts, actions, rewards = [], [], []
        for step, infos in enumerate(self.pull_infos):
            for env_index, info in enumerate(infos):
                if info["hindsight"] is None:
                    continue
                context, reward = info["hindsight"]
                context = np.asarray(context, dtype=space.dtype).reshape(space.shape)
                if np.all(np.isfinite(context)) and np.all(context >= space.low) and np.all(context <= space.high):
                    contexts.append(context)
                    actions.append(buffer.actions[env_index * buffer.buffer_size + step])  # as get() flattened it
                    rewards.append(float(reward))
        action_shape = (len(actions), *self.policy.action_space.shape)  # also when no pull was relabelled
        return (
            th.as_tensor(np.array(contexts, dtype=space.dtype).reshape(-1, *space.shape), device=device),
            th.as_tensor(np.array(actions, dtype=np.float32).reshape(action_shape), device=device),
            th.as_tensor(np.array(rewards, dtype=np.float32), device=device),
        )
