"""GenRL: EM policy training in the latent space of a generative model (paper section 4, Algorithm 1)."""

from __future__ import annotations

import collections
import copy
import inspect
import io
import os
import pathlib
from typing import Any, ClassVar, Literal, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.distributions import Distribution, kl_divergence
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import explained_variance

from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl.averaging import averaged_copy, update_average
from sb3_genrl.genrl.e_step import kl_penalty_e_step, trpo_e_step
from sb3_genrl.genrl.policies import (
    BoxScaler,
    ContextStdPolicy,
    MlpPolicy,
    MultiInputPolicy,
    default_log_std_init,
    limit_log_std_change,
    log_std_parameters,
)
from sb3_genrl.genrl.regression import mean_parameters, regress_mean
from sb3_genrl.genrl.value import fit_value_function
from sb3_genrl.utils import atomic_path
from sb3_genrl.wrappers import latent_action_env

SelfGenRL = TypeVar("SelfGenRL", bound="GenRL")
NO_HINDSIGHT_INFO = ("hindsight=True needs every pull's info['hindsight']: (context, reward) or None. LatentActionWrapper "
                     "reports it when the task defines hindsight(info) and the context is the task's get_context(); "
                     "this env's info has no such key")
EStep = Literal["trpo", "kl_penalty"]


class GenRL(OnPolicyAlgorithm):
    """GenRL: train ``pi_theta(alpha | s0)`` over a generator's latent space with the paper's EM algorithm.

    Paper: Ghadirzadeh et al., "Training and Evaluation of Deep Policies using Reinforcement Learning and Generative
    Models" (JMLR 23(174), 2022), section 4 and Algorithm 1: eq. 4 is the E-step objective, eq. 5 its TRPO form,
    eq. 6 the M-step.

    Each iteration collects ``N = n_steps * n_envs`` one-step episodes
    (one bandit pull each: context ``s0``, latent action ``alpha ~ pi``, reward ``r`` of the decoded trajectory),
    computes ``A = r - V(s0)``, runs the E-step (optimise a variational copy ``q_phi`` of the policy with eq. 5
    while ``pi_theta`` stays fixed), the M-step (``theta <- phi``) and fits ``V`` to ``r``. Episodes last one step,
    so ``gamma`` and ``gae_lambda`` play no role (both are fixed to 1; SB3's GAE then gives ``A = r - V(s0)``).

    Both ``GenRL(env, generator)`` and ``GenRL("MlpPolicy", env, generator=...)`` work: when the first argument is
    not a policy (an alias such as ``"MlpPolicy"`` or a policy class), it is taken as the env and the second as the
    generator. A raw env (or Gymnasium id) is wrapped in :class:`~sb3_genrl.LatentActionWrapper`; a wrapped env
    (or a VecEnv of wrapped envs) is used as is and provides the generator when none is given.

    Policies with dropout or batch norm (``policy_kwargs``) work as in SB3: rollouts and the E-step see the policy in
    evaluation mode (the E-step's ratio ``q/pi`` then starts at 1 and its KL at 0), the value-function fit in training
    mode. A TRPO step whose KL model has no positive curvature, or whose candidates' distributions are invalid, is
    not taken.

    Logs (``train/``): ``mean_reward``, ``max_reward`` (of the iteration's N episodes), ``kl`` (achieved
    ``KL(q || pi)``), ``entropy``, ``std``, ``value_loss``, ``explained_variance``, ``policy_objective`` and, for the
    TRPO E-step, ``line_search_success``, ``accepted_fraction`` (of the full natural step) and ``step_size``.

    Defaults (the paper states none): the TRPO numerics (``target_kl``, conjugate gradient, line search) are
    sb3-contrib TRPO's; ``N = 64`` episodes per iteration; the initial policy std equals the prior's
    (``log_std_init`` 0 for a normal prior). The value function is fitted harder than sb3-contrib does (50 epochs
    at 3e-3 instead of 10 at 1e-3) and the E/M pair is repeated 3 times per batch: once the policy is narrow, a
    pull's advantage is small next to the value function's error. What these defaults reach on hockey is measured
    by ``benchmarks/genrl_hockey.py --library-defaults`` (results in the README and
    ``benchmarks/results/genrl_hockey_without_hindsight.json``; the tasks' own settings add hindsight relabelling).

    :param policy: the policy (``"MlpPolicy"``, the default; ``"ContextStdPolicy"``, whose spread depends on the
        context, see :class:`~sb3_genrl.genrl.policies.ContextStdPolicy`; or an ``ActorCriticPolicy`` class), or the
        env (see above)
    :param env: the env (raw, wrapped, VecEnv of wrapped envs or Gymnasium id), or the generator (see above)
    :param generator: the trajectory generator, or the path of a saved one (restored with
        ``sb3_genrl.generative.load``); default: the wrapped env's
    :param e_step: ``"trpo"`` (default: a natural-gradient step on eq. 5 with the KL bound ``target_kl`` and a
        backtracking line search) or ``"kl_penalty"`` (eq. 5 taken literally, ``E[q/pi A] - kl_coef KL(q || pi)``,
        maximised by Adam for ``n_e_step_epochs`` epochs)
    :param learning_rate: Adam learning rate of the value function (default 3e-3), can be a schedule
    :param n_steps: episodes per env per iteration; ``N = n_steps * n_envs`` (default 64)
    :param batch_size: minibatch size of the value-function fit and of the KL-penalty E-step (default 64)
    :param n_critic_updates: epochs of the value-function fit per iteration, over the returns of the last
        ``value_history`` batches (default 50)
    :param cg_max_steps: conjugate-gradient iterations of the TRPO E-step (default 15)
    :param cg_damping: damping added to the Fisher-vector product (default 0.1)
    :param line_search_shrinking_factor: step shrinking factor of the backtracking line search (default 0.8)
    :param line_search_max_iter: maximum line-search iterations (default 10)
    :param target_kl: KL bound ``delta`` of the TRPO E-step, ``KL(q || pi) < delta`` (default 0.01)
    :param kl_coef: weight of ``KL(q || pi)`` in the KL-penalty E-step (default 1, as in eq. 5)
    :param n_e_step_epochs: Adam epochs of the KL-penalty E-step (default 10)
    :param n_em_iterations: E-step/M-step pairs per batch, Algorithm 1's inner "repeat" loop (default 3); each
        E-step is bounded relative to the policy of the previous M-step, and importance ratios stay relative to the
        policy that collected the batch
    :param e_step_learning_rate: Adam learning rate of the KL-penalty E-step (default 3e-3)
    :param normalize_advantage: standardise the advantages of a batch before the E-step (default True)
    :param value_history: batches whose returns the value function is fitted on: the current one and those of the
        iterations before it (default 1: the current batch only, as in Algorithm 1). A batch holds one pull per
        context; once the policy is narrow, its pulls are too few to estimate ``V(s0)`` to better than the reward
        differences that the advantage must resolve, and on long runs, where the policy changes little over a few
        iterations, recent batches estimate it better (basketball uses 10 with ``n_critic_updates=10``). The advantages
        of a batch always come from the value function fitted before the batch was collected
    :param max_log_std_change: the most the policy's log standard deviation may change per iteration (per batch),
        in each latent dimension and either way, after the E/M pairs (default ``None``: only ``target_kl`` bounds it,
        as in the paper); with ``ContextStdPolicy``, for every context of the box (see
        :func:`~sb3_genrl.genrl.policies.limit_log_std_change`). The spread's own trust region, decoupled from the
        mean's as in MPO (Abdolmaleki et al., 2018). Within ``target_kl`` alone the spread may collapse within a few
        hundred episodes once the mean is good for some contexts, and the mean's steps, which the KL bound scales with
        the spread, then stall for the others. How fast the spread may anneal: 0.02-0.03 suits budgets of 15000
        episodes and more (basketball: 0.03 with ``ContextStdPolicy``); on hockey, 0.05 ends 10% closer after 3000
        episodes but takes 3-4 times the episodes to get within 5 cm
    :param policy_averaging: decay ``d`` of a moving average of the policy's weights over the iterations (``None``,
        the default: none, as in the paper). The average is kept beside the policy that explores
        (``policy_average``) and ``predict`` acts with it, so do evaluations and saved models; see
        :mod:`sb3_genrl.genrl.averaging`. Basketball's long runs land about 12% closer with ``d = 0.97``
    :param hindsight: relabel each pull with the context it would have solved (default ``False``: no relabelling, as
        in the paper). A pull whose info holds ``info["hindsight"] = (context', r')`` (the context for which its
        trajectory earns the best reward, and that reward: for a goal-reaching task, the point it reached and 0;
        :class:`~sb3_genrl.LatentActionWrapper` asks the task's ``hindsight(info)`` method for it) joins the E-step's
        batch a second time as ``(context', alpha, A' = r' - V(context'))``, its advantage standardised with the
        batch's. The relabelled pull is treated as if ``pi(.|context')`` had drawn it (its ratio ``q/pi`` is taken
        at ``context'``), and it stays inside the same KL bound; the value function is fitted on the pulls as played
        only. Relabelled contexts outside the observation box, and pulls whose info holds ``None`` (nothing reached),
        are left out. The latent-space counterpart of hindsight experience replay (Andrychowicz et al., 2017); needs
        a Box context and ``e_step="trpo"`` (under the KL penalty the ratio of a pull that ``pi`` makes unlikely
        at its new context grows faster than the penalty: that objective has no maximum). On the tasks' tuning
        surrogates hockey's 3000 episodes end 23% closer (1.34 against 1.73 cm) and basketball's 20000 22% closer
        (0.063 against 0.080 m); see ``docs/basketball.md``
    :param hindsight_history: batches whose relabelled pulls join the E-step: the current one and those of the
        iterations before it (default 1: the current batch only). A relabelled pull stays true after the policy has
        moved on (the trajectory of ``alpha`` still reaches ``context'``), so, unlike the pulls as played, it can be
        reused: its ratio ``q/pi`` and its advantage ``r' - V(context')`` are recomputed with the current policy
        and value function at every iteration. Needs ``hindsight=True``. Like the value history's batches, the kept
        pulls are not saved with the model: a loaded model starts keeping them anew. With ``K = 30`` the tasks'
        tuning surrogates end closer still: hockey's 3000 episodes 1.08 cm (1.34 with ``K = 1``), basketball's 20000
        0.056 m (0.063); see ``docs/basketball.md``
    :param hindsight_regression: Adam steps per iteration that fit the policy's mean to the kept relabelled pulls,
        after the E/M pairs (default 0: none, as in the paper). A relabelled pull pairs a latent action with the
        context it solves best, so the fit learns the context-to-action map directly (see
        :mod:`sb3_genrl.genrl.regression`); its loss is logged as ``train/hindsight_regression_loss``. The spread is
        left to the E-step and ``max_log_std_change``. Needs ``hindsight=True``. On hockey's tuning surrogate
        (3000 episodes, the last 120 batches of 16 pulls kept, a 64 x 64 x 64 policy network) 512 steps end at
        0.36 cm against 0.82 cm without (256: 0.45 cm); a few steps do worse than none (8: 0.89 cm); see
        ``docs/basketball.md``
    :param hindsight_regression_lr: Adam learning rate of the hindsight regression (default 1e-3)
    :param hindsight_regression_batch_size: relabelled pulls per step of the hindsight regression, drawn with
        replacement from the kept ones (default 256)
    :param hindsight_regression_weighted: weight each pull's error in the hindsight regression by the current
        policy's density at it relative to its mode (default False; see
        :func:`~sb3_genrl.genrl.regression.regress_mean`), for tasks where distant latent actions reach the same
        context: a basketball throw that bounces comes down through the rim's height twice, and the unweighted fit
        averages the two ways to a basket (basketball, 20000 episodes, seeds 0 and 1: 0.043 and 0.042 m against
        0.086 and 0.047 m unweighted and 0.057 and 0.052 m without the regression; see ``docs/basketball.md``)
    :param latent_clip: action box half-width (prior stds) when wrapping a raw env with a normal-prior generator
    :param stats_window_size: episodes averaged in the ``rollout/`` logs
    :param tensorboard_log: TensorBoard log folder (None: no TensorBoard)
    :param policy_kwargs: extra policy arguments (``net_arch``, ``log_std_init``, ...)
    :param verbose: 0 no output, 1 info, 2 debug
    :param seed: seed of the random generators (torch, numpy, env)
    :param device: torch device ("auto": GPU when available)
    :param _init_setup_model: build the networks now (``load()`` passes False)
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy, "MultiInputPolicy": MultiInputPolicy, "ContextStdPolicy": ContextStdPolicy}
    policy: ActorCriticPolicy

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
        value_history: int = 1,
        policy_averaging: float | None = None,
        hindsight: bool = False,
        hindsight_history: int = 1,
        hindsight_regression: int = 0,
        hindsight_regression_lr: float = 1e-3,
        hindsight_regression_batch_size: int = 256,
        hindsight_regression_weighted: bool = False,
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
        _check_hyperparameters(e_step=e_step, n_em_iterations=n_em_iterations, max_log_std_change=max_log_std_change,
                               value_history=value_history, policy_averaging=policy_averaging, hindsight=hindsight,
                               hindsight_history=hindsight_history, hindsight_regression=hindsight_regression,
                               hindsight_regression_lr=hindsight_regression_lr,
                               hindsight_regression_batch_size=hindsight_regression_batch_size,
                               hindsight_regression_weighted=hindsight_regression_weighted)
        env, policy_kwargs = self._latent_env(env, generator, latent_clip, policy_kwargs, device)
        super().__init__(
            policy, env,  # type: ignore[arg-type]
            learning_rate=learning_rate, n_steps=n_steps,
            gamma=1.0, gae_lambda=1.0,  # one-step episodes: no discounting, A = r - V(s0)
            ent_coef=0.0, vf_coef=0.0,  # the value function is fitted separately (Algorithm 1, last line)
            max_grad_norm=0.0, use_sde=False, sde_sample_freq=-1, stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log, policy_kwargs=policy_kwargs, verbose=verbose, seed=seed, device=device,
            _init_setup_model=False, supported_action_spaces=(spaces.Box,),
        )
        if normalize_advantage and self.env is not None and self.n_steps * self.env.num_envs < 2:
            raise ValueError(f"normalize_advantage needs n_steps * n_envs >= 2 episodes, got {self.n_steps * self.n_envs}")
        self.e_step, self.target_kl, self.kl_coef = e_step, target_kl, kl_coef
        self.batch_size, self.n_critic_updates, self.value_history = batch_size, n_critic_updates, int(value_history)
        self.cg_max_steps, self.cg_damping = cg_max_steps, cg_damping
        self.line_search_shrinking_factor, self.line_search_max_iter = line_search_shrinking_factor, line_search_max_iter
        self.n_e_step_epochs, self.e_step_learning_rate = n_e_step_epochs, e_step_learning_rate
        self.n_em_iterations, self.normalize_advantage = int(n_em_iterations), normalize_advantage
        self.max_log_std_change, self.latent_clip, self.policy_averaging = max_log_std_change, latent_clip, policy_averaging
        self.hindsight, self.hindsight_history = hindsight, int(hindsight_history)
        self.hindsight_regression, self.hindsight_regression_lr = int(hindsight_regression), hindsight_regression_lr
        self.hindsight_regression_batch_size = int(hindsight_regression_batch_size)
        self.hindsight_regression_weighted = bool(hindsight_regression_weighted)
        self._pull_infos: list[list[dict[str, Any]]] = []  # the infos of the rollout's pulls, step by step (hindsight)
        if _init_setup_model:
            self._setup_model()

    def _latent_env(self, env: Any, generator: TrajectoryGenerator | str | None, latent_clip: float,
                  policy_kwargs: dict[str, Any] | None, device: th.device | str) -> tuple[Any, dict[str, Any]]:
        """Set ``generator`` and ``generator_path``; the env in its latent-action wrapper, and the policy arguments
        completed with the prior's spread and, for Box contexts, :class:`BoxScaler`. A generator given as a file is
        loaded onto ``device``."""
        self.generator_path: str | None = None
        if isinstance(generator, str | os.PathLike):
            self.generator_path = os.path.abspath(generator)
            generator = _load_generator(self.generator_path, device)
        env, self.generator = latent_action_env(env, generator, latent_clip=latent_clip)  # type: ignore[arg-type]
        policy_kwargs = dict(policy_kwargs or {})
        if self.generator is not None:
            policy_kwargs.setdefault("log_std_init", default_log_std_init(self.generator.prior))
        if isinstance(getattr(env, "observation_space", None), spaces.Box):
            policy_kwargs.setdefault("features_extractor_class", BoxScaler)  # bounded contexts onto [-1, 1]
        return env, policy_kwargs

    @classmethod
    def _is_policy(cls, policy: Any) -> bool:
        """Whether ``policy`` names a policy (an alias or a policy class) rather than an env."""
        if isinstance(policy, str):
            return policy in cls.policy_aliases
        return isinstance(policy, type) and issubclass(policy, BasePolicy)

    def train(self) -> None:
        """One EM iteration (Algorithm 1) on the N episodes in the rollout buffer."""
        # The E-step evaluates pi and q in evaluation mode, the mode that collected the batch (dropout off, batch-norm
        # running statistics): q/pi = 1 and KL(q || pi) = 0 at phi = theta. Only the value function trains in
        # training mode.
        self.policy.set_training_mode(False)
        self._update_learning_rate(self.policy.optimizer)

        # One episode per bandit pull (section 4): the buffer holds {s_i, alpha_i, r_i}, i = 1..N, with
        # alpha_i ~ pi_theta(.|s_i). Each episode ends after one step, so returns = r_i and A_i = r_i - V(s_i).
        data = next(self.rollout_buffer.get(batch_size=None))
        observations, actions, log_prob_pi = data.observations, data.actions, data.old_log_prob
        advantages = data.advantages
        advantage_mean, advantage_std = (advantages.mean(), advantages.std() + 1e-8) if self.normalize_advantage else (0, 1)
        advantages = (advantages - advantage_mean) / advantage_std
        batch = (observations, actions, log_prob_pi, advantages)
        if self.hindsight:  # the relabelled pulls join the E-step's batch (see the class docstring)
            relabelled = self._hindsight_batch(advantage_mean, advantage_std)
            batch = tuple(th.cat([played, extra]) for played, extra in zip(batch, relabelled, strict=True))
            self.logger.record("train/hindsight_pulls", len(relabelled[0]) / len(observations))

        log_std_before = log_std_parameters(self.policy)
        for _ in range(self.n_em_iterations):  # Algorithm 1's inner loop: repeat E-step and M-step on the batch
            # E-step (eq. 4-5): the variational policy q_phi starts as a copy of pi_theta (phi <- theta) and is
            # optimised on E_{alpha ~ pi}[q/pi A] - KL(q || pi) while pi_theta stays fixed.
            variational_policy = copy.deepcopy(self.policy)  # in evaluation mode, as pi
            stats = self._e_step(variational_policy, batch)
            with th.no_grad():
                q_distribution = variational_policy.get_distribution(observations)
                stats["kl"] = kl_divergence(q_distribution, self._pi(observations)).mean().item()  # achieved KL(q || pi)

            # M-step (eq. 6): q and pi share one architecture, so argmin_theta KL(q || pi_theta) is theta <- phi.
            self.policy.load_state_dict(variational_policy.state_dict())

        if self.max_log_std_change is not None:  # the spread's own trust region (see the class docstring)
            limit_log_std_change(self.policy, log_std_before, self.max_log_std_change)

        self.policy.set_training_mode(True)
        if self.hindsight_regression and len(relabelled[0]):  # the mean fitted to the kept relabelled pulls
            losses = regress_mean(self.policy, self.hindsight_optimizer, relabelled[0], relabelled[1],
                                  steps=self.hindsight_regression, batch_size=self.hindsight_regression_batch_size,
                                  weighted=self.hindsight_regression_weighted)
            stats["hindsight_regression_loss"] = float(np.mean(losses))
        # Value function (Algorithm 1, last line): V = argmin_V' sum_i (V'(s_i) - r_i)^2, by Adam on minibatches.
        value_losses = self._fit_value_function()
        self.policy.set_training_mode(False)

        self._n_updates += 1
        if self.policy_averaging is not None:
            update_average(self.policy_average, self.policy, self.policy_averaging, self._n_updates)
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

    def _update_info_buffer(self, infos: list[dict[str, Any]], dones: np.ndarray | None = None) -> None:
        super()._update_info_buffer(infos, dones)
        if self.hindsight:
            if not all("hindsight" in info for info in infos):  # refused at the first pull, not after a rollout
                raise ValueError(NO_HINDSIGHT_INFO)
            self._pull_infos.append(infos)

    def collect_rollouts(self, env: Any, callback: Any, rollout_buffer: Any, n_rollout_steps: int) -> bool:
        self._pull_infos = []
        return super().collect_rollouts(env, callback, rollout_buffer, n_rollout_steps)

    def _hindsight_batch(self, advantage_mean: th.Tensor | float, advantage_std: th.Tensor | float,
                         ) -> tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor]:
        """The relabelled pulls of this rollout and of the ``hindsight_history - 1`` before it: contexts, latent
        actions, their log-probabilities under the current policy at the relabelled contexts, and advantages
        ``r' - V(context')`` standardised like the batch's."""
        buffer, space = self.rollout_buffer, self.observation_space
        if len(self._pull_infos) != buffer.buffer_size or not buffer.generator_ready:  # (train() has called get())
            raise RuntimeError(f"hindsight: {len(self._pull_infos)} steps of infos for a rollout of {buffer.buffer_size}")
        contexts, actions, rewards = [], [], []
        for step, infos in enumerate(self._pull_infos):
            for env_index, info in enumerate(infos):
                if info["hindsight"] is None:
                    continue
                context, reward = info["hindsight"]
                context = np.asarray(context, dtype=space.dtype).reshape(space.shape)
                if np.all(np.isfinite(context)) and np.all(context >= space.low) and np.all(context <= space.high):
                    contexts.append(context)
                    actions.append(buffer.actions[env_index * buffer.buffer_size + step])  # as get() flattened it
                    rewards.append(float(reward))
        action_shape = (len(actions), *self.action_space.shape)  # also when no pull was relabelled
        self._hindsight_memory.append((
            th.as_tensor(np.array(contexts, dtype=space.dtype).reshape(-1, *space.shape), device=self.device),
            th.as_tensor(np.array(actions, dtype=np.float32).reshape(action_shape), device=self.device),
            th.as_tensor(np.array(rewards, dtype=np.float32), device=self.device)))
        observations, action_tensor, reward_tensor = (th.cat(part) for part in zip(*self._hindsight_memory, strict=True))
        with th.no_grad():  # the current policy and value function, also for the pulls of earlier batches
            log_prob = self.policy.get_distribution(observations).log_prob(action_tensor)
            values = self.policy.predict_values(observations).flatten()
        advantages = (reward_tensor.to(values.dtype) - values - advantage_mean) / advantage_std
        return observations, action_tensor, log_prob, advantages

    def _pi(self, observations: th.Tensor) -> Distribution:
        """The fixed policy pi_theta(.|s) (no gradient)."""
        with th.no_grad():
            return self.policy.get_distribution(observations)

    def _e_step(self, q: ActorCriticPolicy, batch: tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor]) -> dict[str, float]:
        """E-step (eq. 4-5) on ``q``, a copy of the policy: the TRPO step or the KL-penalty variant."""
        if self.e_step == "trpo":
            return trpo_e_step(q, self.policy, batch, target_kl=self.target_kl, cg_max_steps=self.cg_max_steps,
                               cg_damping=self.cg_damping, line_search_shrinking_factor=self.line_search_shrinking_factor,
                               line_search_max_iter=self.line_search_max_iter)
        return kl_penalty_e_step(q, self.policy, batch, kl_coef=self.kl_coef, n_epochs=self.n_e_step_epochs,
                                 batch_size=self.batch_size, learning_rate=self.e_step_learning_rate)

    def _setup_model(self) -> None:
        super()._setup_model()
        extractor = self.policy.pi_features_extractor
        if (isinstance(self.policy, ContextStdPolicy) and self.max_log_std_change is not None
                and not (isinstance(extractor, BoxScaler) and extractor.all_bounded)):
            raise ValueError("max_log_std_change with ContextStdPolicy bounds the log std's change over all contexts, "
                             "which needs a bounded Box context scaled by BoxScaler (the default for Box contexts); got "
                             f"{type(extractor).__name__} on {self.observation_space}")
        if self.hindsight and not isinstance(self.observation_space, spaces.Box):
            raise ValueError(f"hindsight=True relabels Box contexts; this env's context space is {self.observation_space}")
        # (observations, returns) of the last value_history batches, for the value-function fit
        self._value_memory: collections.deque[tuple[Any, th.Tensor]] = collections.deque(maxlen=self.value_history)
        # (contexts, latent actions, rewards) relabelled in the last hindsight_history batches
        self._hindsight_memory: collections.deque[tuple[th.Tensor, th.Tensor, th.Tensor]] = collections.deque(
            maxlen=self.hindsight_history)
        self.policy_average = None if self.policy_averaging is None else averaged_copy(self.policy)
        # Adam over the policy's mean for the hindsight regression; it keeps its moments from iteration to iteration
        self.hindsight_optimizer = (th.optim.Adam(mean_parameters(self.policy), lr=self.hindsight_regression_lr)
                                    if self.hindsight_regression else None)

    def predict(self, observation: np.ndarray | dict[str, np.ndarray], state: Any = None, episode_start: Any = None,
                deterministic: bool = False) -> tuple[np.ndarray, Any]:
        """Like SB3's ``predict``; with ``policy_averaging``, the averaged policy acts."""
        return (self.policy_average or self.policy).predict(observation, state, episode_start, deterministic)

    # States saved only when their setting is on (see _get_torch_save_params and set_parameters)
    OPTIONAL_STATES: ClassVar[tuple[str, ...]] = ("policy_average", "hindsight_optimizer")

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, variables = super()._get_torch_save_params()
        return (state_dicts + ["policy_average"] * (self.policy_averaging is not None)
                + ["hindsight_optimizer"] * (self.hindsight_regression > 0), variables)

    def set_parameters(self, load_path_or_dict: str | dict[str, Any], exact_match: bool = True,
                       device: th.device | str = "auto") -> None:
        """Like SB3's ``set_parameters``, for a model whose ``policy_averaging`` or ``hindsight_regression`` was
        switched on or off at load (``GenRL.load(..., policy_averaging=None)``): the saved state of a setting that is
        now off is dropped, and one that is now on but was not saved starts afresh (the average from the loaded
        policy, the regression's Adam without moments). The regression's learning rate is this model's
        ``hindsight_regression_lr``, not the saved optimizer's."""
        from stable_baselines3.common.save_util import load_from_zip_file

        params = dict(load_path_or_dict if isinstance(load_path_or_dict, dict)
                      else load_from_zip_file(load_path_or_dict, device=device, load_data=False)[1])
        fresh = []
        for name in self.OPTIONAL_STATES:
            if getattr(self, name) is None:
                params.pop(name, None)
            elif name not in params:
                fresh.append(name)
                params[name] = getattr(self, name).state_dict()
        super().set_parameters(params, exact_match=exact_match, device=device)
        if "policy_average" in fresh:  # average from the policy just loaded, not the one this model was built with
            self.policy_average = averaged_copy(self.policy)
        if self.hindsight_optimizer is not None:
            for group in self.hindsight_optimizer.param_groups:
                group["lr"] = self.hindsight_regression_lr

    def _fit_value_function(self) -> list[float]:
        """Fit ``V`` to the returns of the last ``value_history`` batches; the minibatch losses."""
        data = next(self.rollout_buffer.get(batch_size=None))
        self._value_memory.append((data.observations, data.returns))
        return fit_value_function(self.policy, self._value_memory, epochs=self.n_critic_updates,
                                  batch_size=self.batch_size)

    def predict_trajectory(self, observation: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """The trajectory ``g(alpha)`` for the policy's latent action given a context: ``(T, M)``, or ``(n, T, M)``."""
        if self.generator is None:
            raise ValueError("this GenRL model has no generator: pass generator= to GenRL.load()")
        alpha, _ = self.predict(observation, deterministic=deterministic)
        single = alpha.ndim == 1
        trajectories = self.generator.decode(self.generator.check_latent(alpha))
        return np.asarray(trajectories[0] if single else trajectories)

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """Like SB3's ``set_env``; a raw env is wrapped with this model's generator first."""
        env, _ = latent_action_env(env, self.generator, latent_clip=self.latent_clip)
        super().set_env(env, force_reset=force_reset)  # type: ignore[arg-type]

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "generator", "_value_memory", "policy_average", "_pull_infos",
                "_hindsight_memory", "hindsight_optimizer"]

    def save(self, path: str | pathlib.Path | io.BufferedIOBase, exclude: Any = None, include: Any = None) -> None:
        """Save like SB3, atomically for a file path (a ``.zip`` suffix is added when there is none, as SB3 does).

        An in-memory generator (no known path) is also saved as ``<name>.generator.pt`` beside it.
        """
        if not isinstance(path, str | pathlib.Path):
            super().save(path, exclude=exclude, include=include)
            return
        final = pathlib.Path(path)
        final = final if final.suffix else final.with_name(final.name + ".zip")
        if self.generator_path is None and self.generator is not None:
            try:
                self.generator.save(str(_generator_file(final)))
            except NotImplementedError:
                pass  # a generator that cannot be saved: GenRL.load then needs generator=
        with atomic_path(final) as tmp:
            super().save(tmp, exclude=exclude, include=include)

    @classmethod
    def load(  # type: ignore[override]
        cls: type[SelfGenRL],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,
        device: th.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        *,
        generator: TrajectoryGenerator | str | None = None,
        **kwargs: Any,
    ) -> SelfGenRL:
        """Load like SB3. The generator is ``generator`` when given, else the saved path or ``<name>.generator.pt``.

        Without any generator the model still predicts latent actions; ``predict_trajectory`` then raises.
        """
        from stable_baselines3.common.save_util import load_from_zip_file

        data, _, _ = load_from_zip_file(path, device=device, custom_objects=custom_objects, load_data=True)
        data = data or {}
        if isinstance(path, io.BufferedIOBase):
            path.seek(0)
        generator_path = os.path.abspath(generator) if isinstance(generator, str | os.PathLike) else None
        if generator is None:  # the saved generator path, else the file saved beside the model
            candidates = [data.get("generator_path")]
            candidates += [_generator_file(path)] if isinstance(path, str | pathlib.Path) else []
            generator_path = next((str(p) for p in candidates if p is not None and os.path.isfile(p)), None)
        if generator_path is not None:  # onto the model's device, as SB3 loads the policy
            generator = _load_generator(generator_path, device)
        if env is not None:  # a raw env is wrapped as at training time
            latent_clip = kwargs.get("latent_clip", data.get("latent_clip", 3.0))
            env, generator = latent_action_env(env, generator, latent_clip=latent_clip)  # type: ignore[arg-type]
        model = super().load(path, env, device, custom_objects, print_system_info, force_reset, **kwargs)
        model.generator = generator  # type: ignore[assignment]
        if isinstance(generator, TrajectoryGenerator) and generator_path is not None and model.generator_path is None:
            model.generator_path = generator_path
        return model

    def learn(self: SelfGenRL, total_timesteps: int, callback: MaybeCallback = None, log_interval: int = 1,
              tb_log_name: str = "GenRL", reset_num_timesteps: bool = True, progress_bar: bool = False) -> SelfGenRL:
        """Train for ``total_timesteps`` episodes (one step = one episode = one trajectory played)."""
        return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)


def check_hyperparameters(settings: dict[str, Any]) -> None:
    """Refuse, before any work, the GenRL settings that ``GenRL(**settings)`` would refuse (the values that SB3 does
    not check itself), each missing one taken at GenRL's default."""
    defaults = inspect.signature(GenRL.__init__).parameters
    _check_hyperparameters(**{name: settings.get(name, defaults[name].default)
                              for name in inspect.signature(_check_hyperparameters).parameters})


def _check_hyperparameters(*, e_step: str, n_em_iterations: int, max_log_std_change: float | None,
                           value_history: int, policy_averaging: float | None, hindsight: bool,
                           hindsight_history: int, hindsight_regression: int, hindsight_regression_lr: float,
                           hindsight_regression_batch_size: int, hindsight_regression_weighted: bool) -> None:
    """Refuse GenRL settings that SB3 does not check itself, with the setting's name."""
    if e_step not in ("trpo", "kl_penalty"):
        raise ValueError(f"e_step must be 'trpo' or 'kl_penalty', got {e_step!r}")
    for name, value in (("n_em_iterations", n_em_iterations), ("value_history", value_history),
                        ("hindsight_history", hindsight_history),
                        ("hindsight_regression_batch_size", hindsight_regression_batch_size)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if max_log_std_change is not None and not max_log_std_change > 0:
        raise ValueError(f"max_log_std_change must be positive or None, got {max_log_std_change!r}")
    if policy_averaging is not None and not 0 < policy_averaging < 1:
        raise ValueError(f"policy_averaging must be between 0 and 1 (exclusive) or None, got {policy_averaging!r}")
    if not isinstance(hindsight, bool | np.bool_):
        raise ValueError(f"hindsight must be True or False, got {hindsight!r}")
    if hindsight and e_step != "trpo":
        raise ValueError("hindsight=True needs e_step='trpo': a relabelled pull that pi makes unlikely at its new context "
                         "has a ratio q/pi that grows exponentially as q moves towards it, faster than the KL penalty "
                         "grows, so the KL-penalty E-step's objective has no maximum (TRPO's step keeps the KL bound)")
    if hindsight_history != 1 and not hindsight:
        raise ValueError(f"hindsight_history={hindsight_history!r} keeps relabelled pulls, which needs hindsight=True")
    if isinstance(hindsight_regression, bool) or int(hindsight_regression) != hindsight_regression or hindsight_regression < 0:
        raise ValueError(f"hindsight_regression must be a non-negative integer (Adam steps), got {hindsight_regression!r}")
    if not hindsight_regression_lr > 0:
        raise ValueError(f"hindsight_regression_lr must be positive, got {hindsight_regression_lr!r}")
    if hindsight_regression and not hindsight:
        raise ValueError(f"hindsight_regression={hindsight_regression!r} fits the policy to relabelled pulls, which "
                         "needs hindsight=True")
    if not isinstance(hindsight_regression_weighted, bool | np.bool_):
        raise ValueError(f"hindsight_regression_weighted must be True or False, got {hindsight_regression_weighted!r}")
    if hindsight_regression_weighted and not hindsight_regression:
        raise ValueError("hindsight_regression_weighted=True weights the hindsight regression's pulls, which needs "
                         "hindsight_regression > 0")


def _generator_file(path: str | pathlib.Path) -> pathlib.Path:
    """``dir/model.zip`` -> ``dir/model.generator.pt``."""
    path = pathlib.Path(path)
    if path.suffix == ".zip":
        path = path.with_suffix("")
    return path.with_name(path.name + ".generator.pt")


def _load_generator(path: str, device: th.device | str) -> TrajectoryGenerator:
    from sb3_genrl.generative import load  # imported lazily: the model classes are only needed here

    return load(path, device=device)
