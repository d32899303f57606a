"""Policies for GenRL: ``pi_theta(alpha | s0)``, a Gaussian over the latent action given the task context.

GenRL uses SB3's actor-critic policies: an MLP maps the context ``s0`` to the mean of a diagonal Gaussian over
``alpha`` with a state-independent log standard deviation, and a separate MLP head gives the value ``V(s0)``.
:class:`ContextStdPolicy` (alias ``"ContextStdPolicy"``) lets the log standard deviation depend on the context.
:class:`~sb3_genrl.GenRL` sets ``log_std_init`` from the generator's prior unless the user gives it (see
:func:`default_log_std_init`), so that the initial policy explores about as widely as the prior, and, for a Box
context, the features extractor :class:`BoxScaler`, which maps the context's bounded box onto ``[-1, 1]`` (a small
goal region would otherwise need large first-layer weights, which trust-region steps grow slowly).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.distributions import DiagGaussianDistribution, Distribution
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy, MultiInputActorCriticPolicy
from stable_baselines3.common.preprocessing import get_action_dim, is_image_space
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule

from sb3_genrl.generative.base import Prior

MlpPolicy = ActorCriticPolicy
MultiInputPolicy = MultiInputActorCriticPolicy


# Names of the value function's parameters in SB3's actor-critic policies: its head, its branch of the MLP and,
# when the features extractor is not shared, its own extractor.
CRITIC_PREFIXES = ("value_net.", "mlp_extractor.value_net.", "vf_features_extractor.")


def actor_parameters(policy: ActorCriticPolicy) -> list[th.nn.Parameter]:
    """The parameters of the policy's action distribution ``pi(alpha | s)``: all but the value function's.

    :param policy: an SB3 actor-critic policy
    :return: the parameters, in ``named_parameters`` order
    """
    return [parameter for name, parameter in policy.named_parameters() if not name.startswith(CRITIC_PREFIXES)]


def default_log_std_init(prior: Prior) -> float:
    """Log of the prior's standard deviation: 0 for N(0, 1), log(1/sqrt(3)) for U(-1, 1)."""
    return 0.0 if prior == "normal" else float(np.log(1.0 / np.sqrt(3.0)))


def completed_policy_kwargs(
    policy_kwargs: dict[str, Any] | None, prior: Prior | None, observation_space: spaces.Space | None
) -> dict[str, Any]:
    """GenRL's policy arguments: ``policy_kwargs`` with, where not given, the prior's spread as ``log_std_init``
    (:func:`default_log_std_init`) and, for a Box context that is not an image, :class:`BoxScaler` (an image keeps
    SB3's own extractor and its division by 255: NatureCNN for ``"CnnPolicy"``, a flatten for ``"MlpPolicy"``)."""
    policy_kwargs = dict(policy_kwargs or {})
    if prior is not None:
        policy_kwargs.setdefault("log_std_init", default_log_std_init(prior))
    if isinstance(observation_space, spaces.Box) and not is_image_space(observation_space, check_channels=False):
        policy_kwargs.setdefault("features_extractor_class", BoxScaler)  # bounded contexts onto [-1, 1]
    return policy_kwargs


def completed_like(policy_kwargs: dict[str, Any], stored: dict[str, Any]) -> dict[str, Any]:
    """``policy_kwargs`` completed as the ``stored`` ones of a saved model were (what :func:`completed_policy_kwargs`
    added), so that a model loaded with its constructor's own ``policy_kwargs`` passes SB3's check that they equal the
    stored ones."""
    added = {key: stored[key] for key in ("log_std_init", "features_extractor_class") if key in stored}
    return added | policy_kwargs


class BoxScaler(BaseFeaturesExtractor):
    """Flatten a Box observation and map each bounded dimension from ``[low, high]`` onto ``[-1, 1]``.

    Unbounded dimensions pass unchanged.

    :param observation_space: the (Box) observation space
    """

    def __init__(self, observation_space: spaces.Box) -> None:
        super().__init__(observation_space, int(np.prod(observation_space.shape)))
        low = np.asarray(observation_space.low, dtype=np.float64).ravel()
        high = np.asarray(observation_space.high, dtype=np.float64).ravel()
        bounded = np.isfinite(low) & np.isfinite(high) & (high > low)
        centre, half_width = np.zeros_like(low), np.ones_like(low)
        centre[bounded] = (low[bounded] + high[bounded]) / 2  # only bounded entries: inf - inf would warn
        half_width[bounded] = (high[bounded] - low[bounded]) / 2
        self.register_buffer("centre", th.as_tensor(centre, dtype=th.float32))
        self.register_buffer("half_width", th.as_tensor(half_width, dtype=th.float32))
        self.all_bounded = bool(bounded.all())  # then every context's features lie in [-1, 1]
        self.unbounded = th.as_tensor(~bounded)  # the dimensions scale_unbounded may scale (not a buffer: the space's)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return (observations.flatten(1) - self.centre) / self.half_width

    def scale_unbounded(self, contexts: th.Tensor) -> None:
        """Centre each unbounded dimension on its mean over ``contexts`` and scale it by their standard deviation, so
        that the contexts' features have mean 0 and standard deviation 1 there; a dimension whose standard deviation
        is below a thousandth of the largest one's is only centred (a context entry that barely moves, such as a
        robot's start pose, is not blown up into noise). Bounded dimensions keep their box's scaling.

        :param contexts: ``(n, *observation_shape)`` contexts, ``n >= 2``, all finite
        :raises ValueError: for fewer than two contexts, contexts of another shape, or a non-finite entry
        """
        contexts = th.as_tensor(contexts, dtype=th.float32).detach().cpu().flatten(1)  # self.unbounded's device
        if len(contexts) < 2 or contexts.shape[1] != self.centre.numel():
            raise ValueError(
                f"BoxScaler.scale_unbounded: needs at least 2 contexts of {self.centre.numel()} entries each, "
                f"got shape {tuple(contexts.shape)}"
            )
        if not th.isfinite(contexts).all():
            raise ValueError("BoxScaler.scale_unbounded: the contexts hold a non-finite entry (nan or inf)")
        std = contexts.std(0)
        unbounded, moving = self.unbounded, self.unbounded & (std > 0) & (std >= 1e-3 * std.max())
        with th.no_grad():
            self.centre[unbounded.to(self.centre.device)] = contexts.mean(0)[unbounded].to(self.centre.device)
            self.half_width[moving.to(self.centre.device)] = std[moving].to(self.centre.device)


def scale_contexts(policy: ActorCriticPolicy, contexts: th.Tensor) -> None:
    """Scale the unbounded context entries of every features extractor of the policy (one when shared) by ``contexts``
    (:meth:`BoxScaler.scale_unbounded`).

    :raises ValueError: when an extractor is not a :class:`BoxScaler` (a user's ``features_extractor_class``, an
        image's), before any is changed
    """
    extractors = {id(e): e for e in (policy.pi_features_extractor, policy.vf_features_extractor)}.values()
    for extractor in extractors:
        if not isinstance(extractor, BoxScaler):
            raise ValueError(
                "scaling the contexts needs the policy's features extractor to be BoxScaler (GenRL's default for a "
                f"Box context); this policy's is {type(extractor).__name__}"
            )
    for extractor in extractors:
        extractor.scale_unbounded(contexts)


class ContextStdPolicy(ActorCriticPolicy):
    """:data:`MlpPolicy` with a log standard deviation that depends on the context: ``log std(s) = W phi(s) + b``.

    ``phi(s)`` is the output of the features extractor (for a Box context :class:`BoxScaler`: the context scaled onto
    ``[-1, 1]``), and ``W, b`` (``log_std_net``) start at ``W = 0, b = log_std_init``: the policy starts as
    :data:`MlpPolicy` does. The spread may then shrink for the contexts the policy has solved and stay wide for the
    others. Being linear in ``phi``, the largest change of ``log std`` over all contexts of a bounded box is exact:
    :class:`~sb3_genrl.GenRL`'s ``max_log_std_change`` bounds it (see :func:`limit_log_std_change`).

    Takes the arguments of SB3's ``ActorCriticPolicy``; the action space must be a Box (no gSDE).
    """

    def _build(self, lr_schedule: Schedule) -> None:
        if not isinstance(self.action_dist, DiagGaussianDistribution):
            raise ValueError("ContextStdPolicy needs a Box action space and use_sde=False")
        super()._build(lr_schedule)
        del self.log_std  # replaced by log_std_net
        self.log_std_net = th.nn.Linear(self.features_dim, get_action_dim(self.action_space))
        th.nn.init.zeros_(self.log_std_net.weight)
        th.nn.init.constant_(self.log_std_net.bias, self.log_std_init)
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)  # type: ignore[call-arg]

    def _distribution(self, pi_features: th.Tensor, latent_pi: th.Tensor) -> Distribution:
        return self.action_dist.proba_distribution(self.action_net(latent_pi), self.log_std_net(pi_features))  # type: ignore[call-arg]

    def _actor_critic(self, obs: PyTorchObs) -> tuple[Distribution, th.Tensor]:
        """The action distribution and the value for ``obs``, as SB3's ``forward`` computes them."""
        features = self.extract_features(obs)
        pi_features, vf_features = (features, features) if self.share_features_extractor else features
        distribution = self._distribution(pi_features, self.mlp_extractor.forward_actor(pi_features))
        return distribution, self.value_net(self.mlp_extractor.forward_critic(vf_features))

    def forward(self, obs: th.Tensor, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        distribution, values = self._actor_critic(obs)
        actions = distribution.get_actions(deterministic=deterministic)
        log_prob = distribution.log_prob(actions)
        return actions.reshape((-1, *self.action_space.shape)), values, log_prob  # type: ignore[misc]

    def evaluate_actions(self, obs: PyTorchObs, actions: th.Tensor) -> tuple[th.Tensor, th.Tensor, th.Tensor | None]:
        distribution, values = self._actor_critic(obs)
        return values, distribution.log_prob(actions), distribution.entropy()

    def get_distribution(self, obs: PyTorchObs) -> Distribution:
        features = BasePolicy.extract_features(self, obs, self.pi_features_extractor)
        return self._distribution(features, self.mlp_extractor.forward_actor(features))

    def _get_action_dist_from_latent(self, latent_pi: th.Tensor) -> Distribution:
        raise NotImplementedError("ContextStdPolicy's log std needs the features: use get_distribution")


def log_std_parameters(policy: ActorCriticPolicy) -> dict[str, th.Tensor]:
    """A copy of the parameters that set the policy's log std: ``log_std``, or ``log_std_net``'s weight and bias."""
    if isinstance(policy, ContextStdPolicy):
        return {name: value.detach().clone() for name, value in policy.log_std_net.state_dict().items()}
    return {"log_std": policy.log_std.detach().clone()}


def limit_log_std_change(policy: ActorCriticPolicy, before: dict[str, th.Tensor], bound: float) -> None:
    """Bound the change of the policy's log std since ``before`` (:func:`log_std_parameters`) to ``bound``, in every
    latent dimension and for every context.

    A state-independent ``log_std`` is clamped to ``before +- bound``. For :class:`ContextStdPolicy` the change of
    dimension ``k`` at features ``phi`` is ``dW_k . phi + db_k``; over features in ``[-1, 1]^d`` its largest size is
    exactly ``|db_k| + sum_j |dW_kj|`` (at the corner ``phi_j = sign(dW_kj) sign(db_k)``). When the largest over the
    dimensions exceeds ``bound``, the whole change ``(dW, db)`` is scaled by ``bound / largest``: the step keeps its
    direction, as in TRPO's line search. The features must lie in ``[-1, 1]`` (:class:`BoxScaler` on a bounded box;
    :class:`~sb3_genrl.GenRL` checks this).
    """
    with th.no_grad():
        if not isinstance(policy, ContextStdPolicy):
            policy.log_std.copy_(th.clamp(policy.log_std, before["log_std"] - bound, before["log_std"] + bound))
            return
        net = policy.log_std_net
        d_weight, d_bias = net.weight - before["weight"], net.bias - before["bias"]
        largest = (d_bias.abs() + d_weight.abs().sum(dim=1)).max().item()
        if largest > bound:
            net.weight.copy_(before["weight"] + bound / largest * d_weight)
            net.bias.copy_(before["bias"] + bound / largest * d_bias)
