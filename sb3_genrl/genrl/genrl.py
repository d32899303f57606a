"""GenRL: EM policy training in the latent space of a generative model (paper section 4, Algorithm 1)."""

from __future__ import annotations

import collections
import io
import os
import pathlib
from typing import Any, ClassVar, Literal, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback, ConvertCallback
from stable_baselines3.common.distributions import Distribution, kl_divergence
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import explained_variance

from sb3_genrl.checks import SettingError
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl import generator_files
from sb3_genrl.genrl.averaging import averaged_copy, update_average
from sb3_genrl.genrl.buffers import FiniteRewardDictRolloutBuffer, FiniteRewardRolloutBuffer
from sb3_genrl.genrl.e_step import kl_penalty_e_step, trpo_e_step, variational_copy
from sb3_genrl.genrl.grouped_pulls import SEED_BOUND, ContextSeeds, leave_one_out_advantages
from sb3_genrl.genrl.hindsight import DEFAULTS as HINDSIGHT_DEFAULTS
from sb3_genrl.genrl.hindsight import HindsightRelabelling
from sb3_genrl.genrl.hindsight_buffer import HindsightRolloutBuffer, PullInfosCallback
from sb3_genrl.genrl.kept_pulls import KeptPulls
from sb3_genrl.genrl.latent_critic import LatentCritic, check_latent_critic_kwargs
from sb3_genrl.genrl.policies import (
    BoxScaler,
    ContextStdPolicy,
    completed_like,
    completed_policy_kwargs,
    limit_log_std_change,
    log_std_parameters,
)
from sb3_genrl.genrl.refits import Refits
from sb3_genrl.genrl.settings import POLICY_ALIASES, SETTINGS, check_genrl_settings
from sb3_genrl.genrl.value import fit_value_function
from sb3_genrl.utils import atomic_path, one_torch_thread
from sb3_genrl.wrappers import latent_action_env

SelfGenRL = TypeVar("SelfGenRL", bound="GenRL")
EStep = Literal["trpo", "kl_penalty"]


class GenRL(OnPolicyAlgorithm):
    """GenRL: train ``pi_theta(alpha | s0)`` over a generator's latent space with the paper's EM algorithm.

    Paper: Ghadirzadeh et al., "Training and Evaluation of Deep Policies using Reinforcement Learning and Generative
    Models" (JMLR 23(174), 2022), section 4 and Algorithm 1 (eq. 4: the E-step's objective, eq. 5: its TRPO form,
    eq. 6: the M-step). Each iteration plays ``batch_episodes = n_steps * n_envs`` one-step episodes (the paper's N;
    :attr:`batch_episodes`), each one bandit pull (context ``s0``, latent action ``alpha ~ pi``, reward ``r`` of the
    decoded trajectory), so ``A = r - V(s0)``.

    ``GenRL(env, generator)`` and ``GenRL("MlpPolicy", env, generator=...)`` both work. A raw env or Gymnasium id is
    wrapped in :class:`~sb3_genrl.LatentActionWrapper`; a wrapped env (or a VecEnv of them) is used as it is and
    provides the generator when none is given. Logs (``train/``): ``mean_reward``, ``max_reward``, ``kl``,
    ``entropy``, ``std``, ``value_loss``, ``explained_variance``, ``policy_objective``; for the TRPO E-step
    ``line_search_success``, ``accepted_fraction``, ``step_size``; with hindsight ``hindsight_pulls`` and
    ``hindsight_regression_loss``, and at a refit ``refit_pairs`` and ``refit_loss``.

    :param policy: ``"MlpPolicy"`` (default; taken as ``"MultiInputPolicy"`` for a ``Dict`` context),
        ``"MultiInputPolicy"``, ``"ContextStdPolicy"`` (a spread that depends on the context,
        :class:`~sb3_genrl.genrl.policies.ContextStdPolicy`) or an ``ActorCriticPolicy`` class; or the env
    :param env: the env (raw, wrapped, a VecEnv of wrapped envs, or a Gymnasium id); or the generator
    :param generator: the trajectory generator, or the path of a saved one (default: the wrapped env's)
    :param e_step: ``"trpo"`` (default: a natural-gradient step on eq. 5 within ``KL(q || pi) < target_kl``, with a
        backtracking line search) or ``"kl_penalty"`` (eq. 5 as written, maximised by Adam)
    :param learning_rate: Adam learning rate of the value function (default 3e-3), or a schedule
    :param n_steps: SB3's rollout length per env, here episodes per env per iteration (default 64): an iteration plays
        ``batch_episodes = n_steps x n_envs`` episodes
    :param batch_size: minibatch size of the value-function fit and of the KL-penalty E-step, at most the episodes of
        one iteration (default 64: an iteration of fewer episodes, as an entry of 16 or 32, is one minibatch of them)
    :param n_critic_updates: epochs of the value-function fit per iteration (default 50)
    :param cg_max_steps: conjugate-gradient iterations of the TRPO E-step (default 15)
    :param cg_damping: damping added to the Fisher-vector product (default 0.1)
    :param line_search_shrinking_factor: step shrinking factor of the line search (default 0.8)
    :param line_search_max_iter: most line-search iterations (default 10)
    :param target_kl: KL bound ``delta`` of the TRPO E-step (default 0.01)
    :param kl_coef: weight of ``KL(q || pi)`` in the KL-penalty E-step (default 1, as in eq. 5)
    :param n_e_step_epochs: Adam epochs of the KL-penalty E-step (default 10)
    :param n_em_iterations: E-step/M-step pairs per batch, Algorithm 1's inner loop (default 3)
    :param e_step_learning_rate: Adam learning rate of the KL-penalty E-step (default 3e-3)
    :param normalize_advantage: standardise a batch's advantages before the E-step (default True)
    :param max_log_std_change: the most the log standard deviation may change per iteration, in each latent
        dimension and, with ``ContextStdPolicy``, for every context (default None: only ``target_kl`` bounds it; 0: the
        spread stays at ``log_std_init``; see :func:`~sb3_genrl.genrl.policies.limit_log_std_change`)
    :param success_kl_floor: scale the TRPO E-step's KL bound by the share of the batch's pulls that failed their own
        context, ``target_kl * max(failed share, success_kl_floor)``, so that the search steps less where the policy
        already solves (default None: ``target_kl`` at every iteration, the paper's); needs the refits of
        ``hindsight_kwargs`` (``refit_every``), whose buffer stores each pull's ``info["is_success"]``
    :param value_history: batches the value function is fitted on: the current one and those before it (default 1)
    :param policy_averaging: decay of a moving average of the policy's weights, with which ``predict`` acts
        (default None: none; see :mod:`sb3_genrl.genrl.averaging`)
    :param hindsight_kwargs: relabel each pull with the context it solved (default None: no relabelling, as in the
        paper): the rollout buffer becomes :class:`~sb3_genrl.genrl.hindsight_buffer.HindsightRolloutBuffer` (SB3's
        ``rollout_buffer_class`` slot), and the settings (``{}``: the defaults) are those of
        :class:`~sb3_genrl.genrl.hindsight.HindsightRelabelling` (``history`` and the ``regression_*``) and of
        :class:`~sb3_genrl.genrl.refits.Refits` (``refit_every``, ``refit_start``, ``refit_steps``). Needs
        ``e_step="trpo"``, a Box context and ``info["hindsight"]`` (not with ``history: 0``, which relabels no pull: the
        refits alone, or the kept pulls); the refits also need ``info["is_success"]``
    :param latent_critic_kwargs: take the E-step's baseline from a critic over latent actions fitted to the pulls of
        the last batches, ``A = r - E_{alpha ~ pi}[Q(s0, alpha)]``, instead of ``A = r - V(s0)`` (default None: the
        paper's ``V``): the arguments of :class:`~sb3_genrl.genrl.latent_critic.LatentCritic` (``{}``: its defaults)
    :param pulls_per_context: play each context this many times, from one reset seed, and take each pull's advantage
        against the mean reward of the others of its context, ``A_i = r_i - mean_{j != i} r_j``, instead of ``r - V(s0)``
        (default 1: one pull per context and the paper's ``V``); ``batch_episodes`` must be a multiple of it, and the
        env's ``reset(seed=...)`` must reproduce its context (see :mod:`sb3_genrl.genrl.grouped_pulls`)
    :param latent_clip: half-width of the latent action box, in prior standard deviations, for a normal-prior
        generator (default 3): a raw env is wrapped with it, an env already wrapped must have it
    :param stats_window_size: episodes averaged in the ``rollout/`` logs (default 100)
    :param tensorboard_log: TensorBoard log folder (default None: no TensorBoard)
    :param policy_kwargs: extra policy arguments (``net_arch``, ``log_std_init``, ...)
    :param verbose: 0 no output, 1 info, 2 debug
    :param seed: seed of the random generators (torch, numpy, env)
    :param device: torch device (default "auto": a GPU when there is one)
    :param _init_setup_model: build the networks now (``load()`` passes False)
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = POLICY_ALIASES
    policy: ActorCriticPolicy
    # States saved only when their setting is on (see _get_torch_save_params and set_parameters)
    OPTIONAL_STATES: ClassVar[tuple[str, ...]] = ("policy_average", "hindsight.optimizer")

    def __init__(
        self,
        policy: str | type[ActorCriticPolicy] | GymEnv = "MlpPolicy",
        env: GymEnv | str | TrajectoryGenerator | None = None,
        generator: TrajectoryGenerator | str | None = None,
        *,
        e_step: EStep = "trpo",
        learning_rate: float | Schedule = 3e-3,
        n_steps: int = 64,
        batch_size: int = 64,
        n_critic_updates: int = 50,
        cg_max_steps: int = 15,
        cg_damping: float = 0.1,
        line_search_shrinking_factor: float = 0.8,
        line_search_max_iter: int = 10,
        target_kl: float = 0.01,
        kl_coef: float = 1.0,
        n_e_step_epochs: int = 10,
        n_em_iterations: int = 3,
        e_step_learning_rate: float = 3e-3,
        normalize_advantage: bool = True,
        max_log_std_change: float | None = None,
        success_kl_floor: float | None = None,
        value_history: int = 1,
        policy_averaging: float | None = None,
        hindsight_kwargs: dict[str, Any] | None = None,
        latent_critic_kwargs: dict[str, Any] | None = None,
        pulls_per_context: int = 1,
        latent_clip: float = 3.0,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        _init_setup_model: bool = True,
    ) -> None:
        if not self._is_policy(policy):  # GenRL(env, generator): shift the positional arguments
            if generator is not None:
                raise TypeError("GenRL(env, generator, generator=...) got the generator twice")
            policy, env, generator = "MlpPolicy", policy, env  # type: ignore[assignment]
        arguments = locals()
        # every setting, checked before any work (sb3_genrl.genrl.settings; SB3 checks few of them, some only partway)
        self.hindsight_kwargs = check_genrl_settings({name: arguments[name] for name in SETTINGS})["hindsight_kwargs"]
        # load() builds the model with the defaults, then sets the saved settings (it checks the env's latent_clip itself)
        env, policy_kwargs = self._latent_env(env, generator, latent_clip, policy_kwargs, device, _init_setup_model)
        super().__init__(
            self._fitting_policy(policy, env),
            env,
            learning_rate=learning_rate,
            n_steps=n_steps,  # type: ignore[arg-type]
            gamma=1.0,
            gae_lambda=1.0,  # one-step episodes: no discounting, A = r - V(s0)
            ent_coef=0.0,
            vf_coef=0.0,  # the value function is fitted separately (Algorithm 1, last line)
            max_grad_norm=0.0,
            use_sde=False,
            sde_sample_freq=-1,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
            supported_action_spaces=(spaces.Box,),
        )
        if normalize_advantage and self.env is not None and self.n_steps * self.env.num_envs < 2:
            raise SettingError(
                f"normalize_advantage needs batch_episodes = n_steps * n_envs >= 2 episodes, got {self.n_steps * self.n_envs}"
            )
        self.pulls_per_context = int(pulls_per_context)
        self._check_pulls_per_context(self.env)
        self._context_root: int | None = None  # the root of the groups' reset seeds (see _setup_learn)
        self.e_step, self.n_em_iterations, self.normalize_advantage = e_step, int(n_em_iterations), normalize_advantage
        self.target_kl, self.cg_max_steps, self.cg_damping = target_kl, cg_max_steps, cg_damping
        self.line_search_shrinking_factor, self.line_search_max_iter = line_search_shrinking_factor, line_search_max_iter
        self.kl_coef, self.n_e_step_epochs, self.e_step_learning_rate = kl_coef, n_e_step_epochs, e_step_learning_rate
        self.batch_size, self.n_critic_updates, self.value_history = batch_size, n_critic_updates, int(value_history)
        self.max_log_std_change, self.latent_clip, self.policy_averaging = max_log_std_change, latent_clip, policy_averaging
        self.latent_critic_kwargs = None if latent_critic_kwargs is None else dict(latent_critic_kwargs)
        self.success_kl_floor = success_kl_floor
        if _init_setup_model:
            self._setup_model()

    @property
    def batch_episodes(self) -> int:
        """The episodes of one EM iteration, ``n_steps * n_envs`` (the paper's N): each env plays ``n_steps`` one-step
        episodes per rollout. Read-only: set ``n_steps`` and the env instead."""
        if getattr(self, "n_envs", None) is None:
            raise AttributeError("batch_episodes is n_steps * n_envs: this model has no env yet (see set_env)")
        return self.n_steps * self.n_envs

    def _check_pulls_per_context(self, env: Any) -> None:
        """Refuse groups of pulls that an iteration's episodes cannot hold whole."""
        pulls = self.pulls_per_context
        if pulls > 1 and env is not None and (self.n_steps * env.num_envs) % pulls:
            raise SettingError(
                f"pulls_per_context={pulls} needs batch_episodes = n_steps * n_envs to be a multiple of it, so that an "
                f"iteration holds whole groups; got {self.n_steps} * {env.num_envs}"
            )

    def _setup_learn(
        self,
        total_timesteps: int,
        callback: MaybeCallback = None,
        reset_num_timesteps: bool = True,
        tb_log_name: str = "run",
        progress_bar: bool = False,
    ) -> tuple[int, BaseCallback]:
        """SB3's ``_setup_learn``; with ``pulls_per_context`` above 1, each env's resets first get their group's seeds
        (:class:`~sb3_genrl.genrl.grouped_pulls.ContextSeeds`) when the env is about to be reset: a new root seed for a
        run that counts its episodes from 0, the recorded one for a run that goes on."""
        self._check_pulls_per_context(self.env)
        if self.pulls_per_context > 1 and (reset_num_timesteps or self._last_obs is None):
            if reset_num_timesteps:
                self._context_root = None  # a new run: new groups
            self.seed_contexts(0 if reset_num_timesteps else None)
        return super()._setup_learn(total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar)

    def seed_contexts(self, first_episode: int | None = None) -> None:
        """With ``pulls_per_context`` above 1, give each env's resets their group's seeds
        (:class:`~sb3_genrl.genrl.grouped_pulls.ContextSeeds`, through the env's ``set_reset_seeds``) from its episode
        ``first_episode`` on; ``learn`` does it before it resets the env, and a resumed run before its first reset.

        :param first_episode: each env's next episode (default None: the run's, ``num_timesteps // n_envs``)
        """
        if self.pulls_per_context == 1:
            return
        if self._context_root is None:  # drawn from torch's generator, which seed= seeds
            self._context_root = int(th.randint(SEED_BOUND, (1,)).item())
        first = self.num_timesteps // self.n_envs if first_episode is None else int(first_episode)
        for index in range(self.n_envs):
            seeds = ContextSeeds(self._context_root, self.pulls_per_context, index, self.n_envs)
            self.env.env_method("set_reset_seeds", seeds, first, indices=[index])

    def _setup_model(self) -> None:
        with one_torch_thread():  # the initial weights too (SB3's orthogonal initialisation differs by thread count)
            self._setup_components()

    def _setup_components(self) -> None:
        # SB3's rollout buffer, refusing a non-finite reward where it enters GenRL (after every wrapper of the env); with
        # hindsight, one that also stores each pull's relabelling (and success, for the refits), as HER is a buffer class
        hindsight = None if self.hindsight_kwargs is None else HINDSIGHT_DEFAULTS | self.hindsight_kwargs
        dict_context = isinstance(self.observation_space, spaces.Dict)
        self.rollout_buffer_class = FiniteRewardDictRolloutBuffer if dict_context else FiniteRewardRolloutBuffer
        self.rollout_buffer_kwargs = {}
        if hindsight is not None:
            self.rollout_buffer_class = HindsightRolloutBuffer
            self.rollout_buffer_kwargs = {"success": bool(hindsight["refit_every"]), "relabel": bool(hindsight["history"])}
        super()._setup_model()
        extractor = self.policy.pi_features_extractor
        if (
            isinstance(self.policy, ContextStdPolicy)
            and self.max_log_std_change is not None
            and not (isinstance(extractor, BoxScaler) and extractor.all_bounded)
        ):
            raise ValueError(
                "max_log_std_change with ContextStdPolicy bounds the log std's change over all contexts, "
                "which needs a bounded Box context scaled by BoxScaler (the default for Box contexts); got "
                f"{type(extractor).__name__} on {self.observation_space}"
            )
        # (observations, returns) of the last value_history batches, for the value-function fit
        self._value_memory: collections.deque[tuple[Any, th.Tensor]] = collections.deque(maxlen=self.value_history)
        self.policy_average = None if self.policy_averaging is None else averaged_copy(self.policy)
        self.hindsight, self.kept_pulls, self.refits = self._hindsight_components(hindsight)
        critic_kwargs = getattr(self, "latent_critic_kwargs", None)  # (absent from a model saved before it existed)
        self.latent_critic = (
            None if critic_kwargs is None else LatentCritic(self.policy, **check_latent_critic_kwargs(critic_kwargs))
        )

    def train(self) -> None:
        """One EM iteration (Algorithm 1) on the ``batch_episodes`` episodes in the rollout buffer."""
        # The E-step evaluates pi and q in evaluation mode, the mode that collected the batch (dropout off, batch-norm
        # running statistics): q/pi = 1 and KL(q || pi) = 0 at phi = theta. Only the value function trains in
        # training mode.
        self.policy.set_training_mode(False)
        self._update_learning_rate(self.policy.optimizer)

        # One episode per bandit pull (section 4): the buffer holds {s_i, alpha_i, r_i}, i = 1..batch_episodes, with
        # alpha_i ~ pi_theta(.|s_i). Each episode ends after one step, so returns = r_i and A_i = r_i - V(s_i).
        if self.pulls_per_context > 1:  # each pull against the other pulls of its context (grouped_pulls)
            self.rollout_buffer.advantages = leave_one_out_advantages(self.rollout_buffer.rewards, self.pulls_per_context)
        data = next(self.rollout_buffer.get(batch_size=None))
        observations, actions, log_prob_pi = data.observations, data.actions, data.old_log_prob
        advantages, stats = data.advantages, {}
        if self.latent_critic is not None:  # the baseline E_{alpha ~ pi}[Q(s0, alpha)] of a critic over latent actions
            advantages, stats = self.latent_critic.advantages(self.policy, observations, actions, data.returns)
        advantage_mean, advantage_std = (advantages.mean(), advantages.std() + 1e-8) if self.normalize_advantage else (0, 1)
        batch = (observations, actions, log_prob_pi, (advantages - advantage_mean) / advantage_std)
        if self.hindsight is not None:  # the relabelled pulls (and those kept for the run) join the E-step's batch
            batch, stats["hindsight_pulls"] = self.hindsight.extend_batch(
                batch, self.rollout_buffer.relabelled_pulls(), advantage_mean, advantage_std
            )

        log_std_before = log_std_parameters(self.policy)
        for _ in range(self.n_em_iterations):  # Algorithm 1's inner loop: repeat E-step and M-step on the batch
            # E-step (eq. 4-5): the variational policy q_phi starts as a copy of pi_theta (phi <- theta) and is
            # optimised on E_{alpha ~ pi}[q/pi A] - KL(q || pi) while pi_theta stays fixed.
            variational_policy = self._q = variational_copy(self.policy, getattr(self, "_q", None))  # eval mode, as pi
            stats.update(self._e_step(variational_policy, batch))
            with th.no_grad():
                q_distribution = variational_policy.get_distribution(observations)
                stats["kl"] = kl_divergence(q_distribution, self._pi(observations)).mean().item()  # achieved KL(q || pi)

            # M-step (eq. 6): q and pi share one architecture, so argmin_theta KL(q || pi_theta) is theta <- phi.
            self.policy.load_state_dict(variational_policy.state_dict())

        if self.max_log_std_change is not None:  # the spread's own trust region
            limit_log_std_change(self.policy, log_std_before, self.max_log_std_change)

        self.policy.set_training_mode(True)
        if self.refits is not None:  # the mean refitted to the run's solving pulls
            stats.update(self.refits.refit(self.rollout_buffer, self.num_timesteps))
        if self.hindsight is not None and (losses := self.hindsight.regress()):  # and fitted to the kept pulls
            stats["hindsight_regression_loss"] = float(np.mean(losses))
        # Value function (Algorithm 1, last line): V = argmin_V' sum_i (V'(s_i) - r_i)^2, by Adam on minibatches.
        value_losses = self._fit_value_function()
        self.policy.set_training_mode(False)

        self._n_updates += 1
        if self.policy_averaging is not None:
            update_average(self.policy_average, self.policy, self.policy_averaging, self._n_updates)
        self._log(stats, value_losses, observations)

    def _log(self, stats: dict[str, float], value_losses: list[float], observations: th.Tensor) -> None:
        rewards, pi = self.rollout_buffer.rewards, self._pi(observations)
        self.logger.record("train/mean_reward", float(np.mean(rewards)))
        self.logger.record("train/max_reward", float(np.max(rewards)))
        for key, value in stats.items():
            self.logger.record(f"train/{key}", value)
        self.logger.record("train/entropy", pi.entropy().mean().item())  # type: ignore[union-attr]
        self.logger.record("train/value_loss", float(np.mean(value_losses)))
        values, returns = self.rollout_buffer.values.flatten(), self.rollout_buffer.returns.flatten()
        self.logger.record("train/explained_variance", float(explained_variance(values, returns)))
        self.logger.record("train/std", pi.distribution.stddev.mean().item())  # type: ignore[attr-defined]
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")

    def _e_step(self, q: ActorCriticPolicy, batch: tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor]) -> dict[str, float]:
        """E-step (eq. 4-5) on ``q``, a copy of the policy: the TRPO step or the KL-penalty variant."""
        if self.e_step == "trpo":
            return trpo_e_step(
                q,
                self.policy,
                batch,
                target_kl=self.kl_bound(),
                cg_max_steps=self.cg_max_steps,
                cg_damping=self.cg_damping,
                line_search_shrinking_factor=self.line_search_shrinking_factor,
                line_search_max_iter=self.line_search_max_iter,
            )
        return kl_penalty_e_step(
            q,
            self.policy,
            batch,
            kl_coef=self.kl_coef,
            n_epochs=self.n_e_step_epochs,
            batch_size=self.minibatch_size,
            learning_rate=self.e_step_learning_rate,
        )

    def kl_bound(self) -> float:
        """The TRPO E-step's KL bound for the batch in the rollout buffer: ``target_kl``, or with ``success_kl_floor``
        ``target_kl`` times the share of the batch's pulls that failed their own context, at least ``success_kl_floor``
        of it."""
        if self.success_kl_floor is None:
            return self.target_kl
        return self.target_kl * max(1.0 - float(np.mean(self.rollout_buffer.successes)), self.success_kl_floor)

    @property
    def minibatch_size(self) -> int:
        """The minibatch of the value-function fit and of the KL-penalty E-step: ``batch_size``, at most the episodes of
        one iteration (``batch_episodes``)."""
        return min(int(self.batch_size), self.batch_episodes)

    def _pi(self, observations: th.Tensor) -> Distribution:
        """The fixed policy pi_theta(.|s) (no gradient)."""
        with th.no_grad():
            return self.policy.get_distribution(observations)

    def _fit_value_function(self) -> list[float]:
        """Fit ``V`` to the returns of the last ``value_history`` batches; the minibatch losses."""
        data = next(self.rollout_buffer.get(batch_size=None))
        self._value_memory.append((data.observations, data.returns))
        return fit_value_function(
            self.policy, self._value_memory, epochs=self.n_critic_updates, batch_size=self.minibatch_size
        )

    def _hindsight_components(
        self, hindsight: dict[str, Any] | None
    ) -> tuple[HindsightRelabelling | None, KeptPulls | None, Refits | None]:
        """The components ``hindsight_kwargs`` (with its defaults filled in) switches on: the relabelling, the pulls
        kept for the whole run, and the refits (with ``refit_every``); all None without hindsight."""
        if hindsight is None:
            return None, None, None
        kept_pulls = KeptPulls(self.observation_space, self.action_space, self.device)  # type: ignore[arg-type]
        regression = {key: value for key, value in hindsight.items() if not key.startswith("refit_")}
        relabelling = HindsightRelabelling(self.policy, kept_pulls=kept_pulls, **regression)
        refits = None
        if hindsight["refit_every"]:
            refits = Refits(
                self.policy,
                every=hindsight["refit_every"],
                start=hindsight["refit_start"],
                steps=hindsight["refit_steps"],
                learning_rate=hindsight["regression_lr"],
                batch_size=hindsight["regression_batch_size"],
            )
        return relabelling, kept_pulls, refits

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, Any]:
        """Like SB3's ``predict``; with ``policy_averaging``, the averaged policy acts."""
        return (self.policy_average or self.policy).predict(observation, state, episode_start, deterministic)

    def predict_trajectory(self, observation: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """The trajectory ``g(alpha)`` for the policy's latent action given a context: ``(T, M)``, or ``(n, T, M)``."""
        if self.generator is None:
            raise ValueError("this GenRL model has no generator: pass generator= to GenRL.load()")
        alpha, _ = self.predict(observation, deterministic=deterministic)
        single = alpha.ndim == 1
        trajectories = self.generator.decode(self.generator.check_latent(alpha))
        return np.asarray(trajectories[0] if single else trajectories)

    def learn(
        self: SelfGenRL,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "GenRL",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfGenRL:
        """Train for ``total_timesteps`` episodes (one step = one episode = one trajectory played). With hindsight, a
        :class:`~sb3_genrl.genrl.hindsight_buffer.PullInfosCallback` comes first among the callbacks: it hands each
        step's infos to the rollout buffer.

        Torch runs on one CPU thread while the model learns (:func:`sb3_genrl.utils.one_torch_thread`)."""
        if isinstance(self.rollout_buffer, HindsightRolloutBuffer):
            given = callback if isinstance(callback, list) else [] if callback is None else [callback]
            callback = [PullInfosCallback(), *(c if isinstance(c, BaseCallback) else ConvertCallback(c) for c in given)]
        with one_torch_thread():
            return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """Like SB3's ``set_env``; a raw env is wrapped with this model's generator first. A wrapped env must hold this
        model's generator and ``latent_clip`` (another generator is refused: the policy would train on it and be saved
        with its own); a model without a generator takes the env's, when it is the one the model recorded."""
        env, generator = self._generator_env(env, self.generator, self.generator_path, self.latent_clip, "this model")
        generator_files.check_recorded_generator(generator, self.generator_sha256, None, "this model")
        super().set_env(env, force_reset=force_reset)  # type: ignore[arg-type]
        self.generator = generator

    def _optional_state(self, name: str) -> Any:
        """The object of an entry of ``OPTIONAL_STATES`` (``"hindsight.optimizer"``: an attribute's), None when off."""
        owner, _, attribute = name.rpartition(".")
        holder = getattr(self, owner) if owner else self
        return None if holder is None else getattr(holder, attribute)

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, variables = super()._get_torch_save_params()
        return state_dicts + [name for name in self.OPTIONAL_STATES if self._optional_state(name) is not None], variables

    def _excluded_save_params(self) -> list[str]:
        return [
            *super()._excluded_save_params(),
            "generator",
            "_value_memory",
            "policy_average",
            "hindsight",
            "kept_pulls",
            "refits",
            "_q",
            "latent_critic",
        ]

    def set_parameters(
        self, load_path_or_dict: str | dict[str, Any], exact_match: bool = True, device: th.device | str = "auto"
    ) -> None:
        """Like SB3's, for a model whose ``policy_averaging`` or hindsight regression was switched on or off at load:
        the saved state of a setting now off is dropped, one now on but not saved starts afresh (the average from the
        loaded policy, the regression's Adam without moments). The regression's learning rate is this model's."""
        params = dict(
            load_path_or_dict
            if isinstance(load_path_or_dict, dict)
            else load_from_zip_file(load_path_or_dict, device=device, load_data=False)[1]
        )
        fresh = []
        for name in self.OPTIONAL_STATES:
            if self._optional_state(name) is None:
                params.pop(name, None)
            elif name not in params:
                fresh.append(name)
                params[name] = self._optional_state(name).state_dict()
        super().set_parameters(params, exact_match=exact_match, device=device)
        if "policy_average" in fresh:  # average from the policy just loaded, not the one this model was built with
            self.policy_average = averaged_copy(self.policy)
        if self.hindsight is not None:
            self.hindsight.set_learning_rate()

    def save(self, path: str | pathlib.Path | io.BufferedIOBase, exclude: Any = None, include: Any = None) -> None:
        """Save like SB3, atomically for a file path (a ``.zip`` suffix is added when there is none, as SB3 does). The
        model records its generator's file (an absolute path); a generator without one (built in memory, or loaded from
        beside another zip), or whose file is gone, is also saved as ``<name>.generator.pt`` beside it."""
        if not isinstance(path, str | pathlib.Path):
            super().save(path, exclude=exclude, include=include)
            return
        final = pathlib.Path(path)
        final = final if final.suffix else final.with_name(final.name + ".zip")
        if self.generator is not None and (self.generator_path is None or not os.path.isfile(self.generator_path)):
            generator_files.save_generator_beside(self.generator, final)
        with atomic_path(final) as tmp:
            super().save(tmp, exclude=exclude, include=include)

    @classmethod
    def load(
        cls: type[SelfGenRL],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,  # type: ignore[override]
        device: th.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        *,
        generator: TrajectoryGenerator | str | None = None,
        **kwargs: Any,
    ) -> SelfGenRL:
        """Load like SB3. The generator is ``generator`` when given, else the saved path or ``<name>.generator.pt``
        (refused when its SHA-256 is not the model's ``generator_sha256``); without any, the env's (checked the same
        way), else none: the model still predicts latent actions, ``predict_trajectory`` raises, and a warning says so.
        A file that is not a GenRL model zip is refused; so is an env wrapped with another generator than the model's,
        and a setting in ``kwargs`` that the constructor would refuse (checked with the saved ones)."""
        data, _, _ = load_from_zip_file(path, device=device, custom_objects=custom_objects, load_data=True)
        data = data or {}
        if isinstance(path, io.BufferedIOBase):
            path.seek(0)
        generator, generator_path = generator_files.saved_generator(path, data, generator, device)  # model's device
        settings = {key: value for key, value in kwargs.items() if key in SETTINGS}
        if settings:  # SB3 sets them without the constructor: checked here, with the saved ones they go together with
            saved = {key: data[key] for key in SETTINGS if key in data and key != "policy_kwargs"}
            check_genrl_settings(saved | settings, f"GenRL.load({path})")
        if isinstance(kwargs.get("policy_kwargs"), dict):  # the constructor's: stored with the defaults added
            kwargs["policy_kwargs"] = completed_like(kwargs["policy_kwargs"], data.get("policy_kwargs", {}))
        if env is not None:  # a raw env is wrapped as at training time; a wrapped one must hold the model's generator
            latent_clip = kwargs.get("latent_clip", data.get("latent_clip", SETTINGS["latent_clip"].default))
            env, generator = cls._generator_env(env, generator, generator_path, latent_clip, path)
            generator_files.check_recorded_generator(generator, data.get("generator_sha256"), None, path)  # the env's
        if generator is None:
            generator_files.warn_without_generator(path, data)
        model = super().load(path, env, device, custom_objects, print_system_info, force_reset, **kwargs)
        model.generator = generator  # type: ignore[assignment]
        # the generator's own file, recorded in the next save; one found beside this zip is saved beside the next
        beside = isinstance(path, str | os.PathLike) and generator_path == os.path.abspath(
            generator_files.generator_file(path)
        )
        model.generator_path = None if beside else generator_path
        return model

    def _latent_env(
        self,
        env: Any,
        generator: TrajectoryGenerator | str | None,
        latent_clip: float,
        policy_kwargs: dict[str, Any] | None,
        device: th.device | str,
        check_latent_clip: bool = True,
    ) -> tuple[Any, dict[str, Any]]:
        """Set ``generator``, ``generator_path`` and ``generator_sha256``; the env in its latent-action wrapper, and the
        policy arguments completed (:func:`~sb3_genrl.genrl.policies.completed_policy_kwargs`). A generator given as a
        file is loaded onto ``device``; one given beside an env that wraps another is refused, and so is an env wrapped
        with another ``latent_clip`` (unless not ``check_latent_clip``)."""
        self.generator_path: str | None = None
        if isinstance(generator, str | os.PathLike):
            self.generator_path = os.path.abspath(generator)
            generator = generator_files.load_generator(self.generator_path, device)
        env, self.generator = self._generator_env(
            env,
            generator,  # type: ignore[arg-type]
            self.generator_path,
            latent_clip,
            check_latent_clip=check_latent_clip,
        )
        self.generator_sha256 = generator_files.generator_digest(self.generator)  # saved, and checked by load()
        prior = None if self.generator is None else self.generator.prior
        return env, completed_policy_kwargs(policy_kwargs, prior, getattr(env, "observation_space", None))

    @staticmethod
    def _generator_env(
        env: Any,
        generator: TrajectoryGenerator | None,
        generator_path: str | None,
        latent_clip: float,
        model: Any = None,
        check_latent_clip: bool = True,
    ) -> tuple[Any, TrajectoryGenerator | None]:
        """The way every env reaches a GenRL model (the constructor, ``set_env``, ``load``): a raw env wrapped with
        ``generator``, or an env already wrapped, refused when its generator is not ``generator`` or its ``latent_clip``
        is not ``latent_clip`` (:func:`~sb3_genrl.genrl.generator_files.check_same_generator`,
        :func:`~sb3_genrl.wrappers.latent_action_env`); with the generator it plays.

        :param model: None for the constructor's own arguments, else the model whose generator ``generator`` is
        :param check_latent_clip: refuse a wrapped env of another ``latent_clip`` (False while ``load()`` builds the model
            with the default settings, before it sets the saved ones)
        """
        generator_files.check_same_generator(generator, env, generator_path, model)
        return latent_action_env(env, generator, latent_clip=latent_clip, check_latent_clip=check_latent_clip)

    @staticmethod
    def _fitting_policy(policy: Any, env: Any) -> Any:
        """``policy``, the default ``"MlpPolicy"`` taken as ``"MultiInputPolicy"`` for a ``Dict`` context."""
        dict_context = isinstance(getattr(env, "observation_space", None), spaces.Dict)
        return "MultiInputPolicy" if policy == "MlpPolicy" and dict_context else policy

    @classmethod
    def _is_policy(cls, policy: Any) -> bool:
        """Whether ``policy`` names a policy (an alias or a policy class) rather than an env."""
        if isinstance(policy, str):
            return policy in cls.policy_aliases
        return isinstance(policy, type) and issubclass(policy, BasePolicy)
