"""The Fisher-vector product of GenRL's TRPO E-step, computed analytically for its diagonal-Gaussian policies.

The E-step's conjugate gradient needs ``H v``, ``H`` the Hessian of ``KL(q || pi)`` (averaged over the batch's ``N``
contexts and the ``d`` latent dimensions, as the E-step's ``kl_divergence(q, pi).mean()`` takes it) in ``q``'s
parameters, at ``q = pi``. For a diagonal Gaussian with mean ``mu(s)``
and log standard deviation ``l(s)``, the KL's first derivatives in ``(mu, l)`` vanish at ``q = pi`` and its second
ones are ``1 / sigma^2`` (mean), ``2`` (log std) and ``0`` (cross terms), so ``H`` is the Fisher matrix

    H = 1/(N d) sum_i  J_mu,i^T diag(1 / sigma_i^2) J_mu,i  +  2 J_l,i^T J_l,i

with ``J`` the Jacobians of the mean and the log std in the parameters. ``H v`` is then one forward pass of
tangents through the mean's MLP (``J v``) and one backward pass (``J^T u``), about half the work of the double
backward pass through autograd's graph of the KL's gradient that sb3-contrib's TRPO takes; in exact arithmetic the
two are equal, in floating point they agree to rounding (``tests/genrl/test_e_step.py``).

Known structures: a mean that is an MLP of linear layers and tanh or ReLU activations on fixed features (a features
extractor without trained parameters), and a log std that is a parameter (SB3's ``MlpPolicy``) or linear in the
features (:class:`~sb3_genrl.genrl.policies.ContextStdPolicy`); :func:`gaussian_fisher` returns ``None`` for others.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy
from torch import nn

from sb3_genrl.genrl.fused import Layer, mlp_layers
from sb3_genrl.genrl.policies import ContextStdPolicy


def _slices(parameters: Sequence[nn.Parameter]) -> dict[int, tuple[int, int]]:
    """Where each parameter sits in the flat vector of ``parameters``: ``id -> (start, end)``."""
    slices, start = {}, 0
    for parameter in parameters:
        slices[id(parameter)] = (start, start + parameter.numel())
        start += parameter.numel()
    return slices


class GaussianFisher:
    """``v -> H v`` for the policy's KL Hessian at its current parameters over ``observations`` (see the module doc).

    :param layers: the mean's MLP (its last layer gives the mean)
    :param spread: the log std's parameter (``MlpPolicy``) or linear layer on the features (``ContextStdPolicy``)
    :param features: the batch's features
    :param std: the policy's standard deviation at the batch, ``(N, latent_dim)``
    :param parameters: the parameters in the order of the flat vectors (exactly the mean's and the log std's)
    """

    def __init__(
        self,
        layers: list[Layer],
        spread: nn.Parameter | nn.Linear,
        features: th.Tensor,
        std: th.Tensor,
        parameters: Sequence[nn.Parameter],
    ) -> None:
        self.slices, self.numel = _slices(parameters), sum(parameter.numel() for parameter in parameters)
        self.layers = [
            (linear.weight.detach(), linear.bias.detach(), id(linear.weight), id(linear.bias)) for linear, _ in layers
        ]
        self.spread, self.features = spread, features
        n = std.numel()  # the KL's terms: contexts times latent dimensions
        self.mean_weight = 1.0 / (n * std.pow(2))  # the KL's second derivative in the mean, over its terms
        self.spread_weight = 2.0 / n  # ... and in the log std
        with th.no_grad():  # each layer's input, and the activations' derivatives at the batch
            self.inputs, self.slopes = [features], []
            for (weight, bias, _, _), (_, activation) in zip(self.layers, layers, strict=True):
                output = th.addmm(bias, self.inputs[-1], weight.t())
                output = output if activation is None else _ACTIVATION[activation](output)
                self.slopes.append(_slope(activation, output))
                self.inputs.append(output)

    def _view(self, vector: th.Tensor, key: int, shape: th.Size) -> th.Tensor:
        """The part of a flat ``vector`` that belongs to the parameter ``key`` (its ``id``), shaped as it."""
        start, end = self.slices[key]
        return vector[start:end].view(shape)

    def __call__(self, vector: th.Tensor) -> th.Tensor:
        """``H vector``, a flat vector in the order of the parameters."""
        with th.no_grad():
            product = th.zeros(self.numel, dtype=vector.dtype, device=vector.device)
            self._mean_product(vector, product)
            self._spread_product(vector, product)
        return product

    def _mean_product(self, vector: th.Tensor, product: th.Tensor) -> None:
        """Add ``J_mu^T diag(1 / (N d sigma^2)) J_mu vector`` to ``product``."""
        tangent = None  # the inputs' tangent: none, the features are fixed
        for index, (weight, bias, weight_key, bias_key) in enumerate(self.layers):
            direction = th.addmm(
                self._view(vector, bias_key, bias.shape), self.inputs[index], self._view(vector, weight_key, weight.shape).t()
            )
            if tangent is not None:
                direction.addmm_(tangent, weight.t())
            tangent = direction if self.slopes[index] is None else direction.mul_(self.slopes[index])
        grad = tangent.mul_(self.mean_weight)  # type: ignore[union-attr]
        for index in reversed(range(len(self.layers))):
            weight, bias, weight_key, bias_key = self.layers[index]
            if self.slopes[index] is not None:
                grad = grad * self.slopes[index]
            self._view(product, weight_key, weight.shape).addmm_(grad.t(), self.inputs[index])
            self._view(product, bias_key, bias.shape).add_(grad.sum(0))
            if index:
                grad = grad @ weight

    def _spread_product(self, vector: th.Tensor, product: th.Tensor) -> None:
        """Add ``2 J_l^T J_l vector / (N d)`` to ``product``."""
        if isinstance(self.spread, nn.Parameter):  # the same log std for every context: J_l = I for each of them
            key = id(self.spread)
            self._view(product, key, self.spread.shape).add_(
                self._view(vector, key, self.spread.shape), alpha=self.spread_weight * len(self.features)
            )
            return
        weight, bias = self.spread.weight, self.spread.bias
        tangent = th.addmm(
            self._view(vector, id(bias), bias.shape), self.features, self._view(vector, id(weight), weight.shape).t()
        ).mul_(self.spread_weight)
        self._view(product, id(weight), weight.shape).addmm_(tangent.t(), self.features)
        self._view(product, id(bias), bias.shape).add_(tangent.sum(0))


_ACTIVATION: dict[type[nn.Module], Callable[[th.Tensor], th.Tensor]] = {nn.Tanh: th.tanh, nn.ReLU: th.relu}


def _slope(activation: type[nn.Module] | None, output: th.Tensor) -> th.Tensor | None:
    """The derivative of ``activation`` at the input that gave ``output`` (``None``: no activation)."""
    if activation is None:
        return None
    if activation is nn.Tanh:
        return 1 - output.pow(2)
    return (output > 0).to(output.dtype)


def gaussian_fisher(
    policy: ActorCriticPolicy, observations: th.Tensor, std: th.Tensor, parameters: Sequence[nn.Parameter]
) -> GaussianFisher | None:
    """The analytic ``v -> H v`` of ``policy``'s KL at ``observations`` over ``parameters`` (its actor's), or
    ``None`` when the policy is not of a known structure (see the module doc).

    :param std: the policy's standard deviation at ``observations``
    """
    if isinstance(observations, dict) or std.dim() != 2:
        return None
    extractor = policy.pi_features_extractor
    layers = mlp_layers([policy.mlp_extractor.policy_net, policy.action_net])
    if layers is None or any(parameter.requires_grad for parameter in extractor.parameters()):
        return None
    spread: nn.Parameter | nn.Linear = policy.log_std_net if isinstance(policy, ContextStdPolicy) else policy.log_std
    if not isinstance(spread, nn.Parameter | nn.Linear) or (isinstance(spread, nn.Linear) and spread.bias is None):
        return None
    known = [p for linear, _ in layers for p in (linear.weight, linear.bias)] + list(
        [spread] if isinstance(spread, nn.Parameter) else [spread.weight, spread.bias]
    )
    if sorted(map(id, known)) != sorted(map(id, parameters)) or len(known) != len(parameters):
        return None
    with th.no_grad():
        features = policy.extract_features(observations, extractor)
    return GaussianFisher(layers, spread, features, std.detach(), parameters)
