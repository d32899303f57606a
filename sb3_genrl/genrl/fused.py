"""Fused fit steps for GenRL's small networks: an MLP's forward and backward passes as a few tensor operations on one
flat parameter vector, and Adam's update of that vector, in place of autograd and ``torch.optim.Adam`` at every step.

GenRL's networks are small (64-wide MLPs), so a step of its fits (the hindsight regression of the policy's mean, the
value function) costs mostly the per-operation overhead of building an autograd graph, running it, and Adam's
per-parameter bookkeeping. Here a step is the same operations that autograd and Adam (``foreach``) would run, called
directly and in the same order: ``addmm`` forward, ``mm`` and ``sum`` backward, ``tanh_backward`` or
``threshold_backward``, then Adam's ``lerp``, ``addcmul``, ``sqrt``, ``div``, ``add`` and ``addcdiv``. The parameters
and the optimizer's state are gathered into flat tensors before a fit and written back after it, so the result is bit
for bit the one of autograd and ``torch.optim.Adam`` (``tests/genrl/test_regression.py``, ``test_value.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch as th
from torch import nn

# Activations the fused passes know: the function (in place, on a fresh layer output), and its derivative as autograd
# computes it from the output
ACTIVATIONS: dict[type[nn.Module], tuple[Callable[[th.Tensor], th.Tensor], Callable[[th.Tensor, th.Tensor], th.Tensor]]] = {
    nn.Tanh: (th.tanh_, lambda grad, output: th.ops.aten.tanh_backward(grad, output)),
    nn.ReLU: (th.relu_, lambda grad, output: th.ops.aten.threshold_backward(grad, output, 0)),
}
Layer = tuple[nn.Linear, type[nn.Module] | None]  # a linear layer and the activation after it (None: none)


def mlp_layers(modules: Sequence[nn.Module]) -> list[Layer] | None:
    """``modules`` (in order; ``nn.Sequential``s are entered) as linear layers each followed by at most one known
    activation (:data:`ACTIVATIONS`), or ``None`` when they are anything else (another module, two activations in a
    row, an activation first)."""
    layers: list[Layer] = []
    flat = [child for module in modules for child in (module if isinstance(module, nn.Sequential) else [module])]
    for module in flat:
        if isinstance(module, nn.Linear) and module.bias is not None:
            layers.append((module, None))
        elif type(module) in ACTIVATIONS and layers and layers[-1][1] is None:
            layers[-1] = (layers[-1][0], type(module))
        else:
            return None
    return layers or None


class FlatAdam:
    """``torch.optim.Adam``'s update of some of its parameters, run on flat copies of them and of their state.

    Builds only for a plain Adam (no weight decay, AMSGrad, maximize, capturable or fused kernel) whose parameters all
    sit in one group and have taken the same number of steps; :meth:`build` returns ``None`` otherwise. The update is
    Adam's ``foreach`` one, operation by operation, which is also its per-parameter one in value.

    :param optimizer: the Adam optimizer
    :param parameters: the parameters to update, in the order of the flat vector
    """

    def __init__(self, optimizer: th.optim.Adam, parameters: Sequence[nn.Parameter]) -> None:
        self.optimizer, self.parameters = optimizer, list(parameters)
        group = next(g for g in optimizer.param_groups if any(p is self.parameters[0] for p in g["params"]))
        self.lr, (self.beta1, self.beta2), self.eps = group["lr"], group["betas"], group["eps"]
        states = [optimizer.state.get(parameter, {}) for parameter in self.parameters]
        self.steps = float(states[0]["step"]) if states[0] else 0.0
        with th.no_grad():
            self.vector = th.cat([parameter.detach().reshape(-1) for parameter in self.parameters])
            self.exp_avg, self.exp_avg_sq = (
                th.cat(
                    [
                        (state[key] if state else th.zeros_like(p)).reshape(-1)
                        for p, state in zip(self.parameters, states, strict=True)
                    ]
                )
                for key in ("exp_avg", "exp_avg_sq")
            )
        self.grad = th.zeros_like(self.vector)

    @classmethod
    def build(cls, optimizer: th.optim.Optimizer, parameters: Sequence[nn.Parameter]) -> FlatAdam | None:
        """A :class:`FlatAdam` for ``parameters`` of ``optimizer``, or ``None`` where it would not be Adam's update."""
        if type(optimizer) is not th.optim.Adam or not parameters:
            return None
        ids = {id(parameter) for parameter in parameters}
        groups = [group for group in optimizer.param_groups if ids & {id(p) for p in group["params"]}]
        if len(groups) != 1 or not ids <= {id(p) for p in groups[0]["params"]}:
            return None
        group = groups[0]
        if (
            any(group.get(key) for key in ("weight_decay", "amsgrad", "maximize", "capturable", "fused", "differentiable"))
            or isinstance(group["lr"], th.Tensor)
            or any(isinstance(beta, th.Tensor) for beta in group["betas"])
        ):
            return None
        states = [optimizer.state.get(parameter, {}) for parameter in parameters]
        if any(bool(state) != bool(states[0]) for state in states):
            return None
        if states[0] and len({float(state["step"]) for state in states}) != 1:
            return None
        if len({(p.dtype, p.device) for p in parameters}) != 1:
            return None
        return cls(optimizer, parameters)  # type: ignore[arg-type]

    def views(self, tensor: th.Tensor) -> list[th.Tensor]:
        """``tensor`` (a flat vector like :attr:`vector`) cut into views shaped as the parameters."""
        views, start = [], 0
        for parameter in self.parameters:
            views.append(tensor[start : start + parameter.numel()].view(parameter.shape))
            start += parameter.numel()
        return views

    def step(self) -> None:
        """One Adam step of :attr:`vector` along :attr:`grad`, as ``torch.optim.Adam`` (``foreach``) takes it."""
        self.steps += 1.0
        self.exp_avg.lerp_(self.grad, 1 - self.beta1)
        self.exp_avg_sq.mul_(self.beta2)
        self.exp_avg_sq.addcmul_(self.grad, self.grad, value=1 - self.beta2)
        step_size = (self.lr / (1 - self.beta1**self.steps)) * -1
        denominator = self.exp_avg_sq.sqrt()
        denominator.div_((1 - self.beta2**self.steps) ** 0.5)
        denominator.add_(self.eps)
        self.vector.addcdiv_(self.exp_avg, denominator, value=step_size)

    def write_back(self) -> None:
        """Copy the vector into the parameters, the moments and the step count into the optimizer's state, and the
        last gradient into the parameters' ``grad`` (where autograd would have left it)."""
        if self.steps == 0:
            return
        with th.no_grad():
            for parameter, value, exp_avg, exp_avg_sq, grad in zip(
                self.parameters, *(self.views(t) for t in (self.vector, self.exp_avg, self.exp_avg_sq, self.grad)), strict=True
            ):
                parameter.copy_(value)
                state = self.optimizer.state[parameter]
                state["step"] = (
                    th.tensor(self.steps, dtype=th.get_default_dtype()) if not state else state["step"].fill_(self.steps)
                )
                state["exp_avg"] = exp_avg.clone()
                state["exp_avg_sq"] = exp_avg_sq.clone()
                parameter.grad = grad.clone()


class FlatMlp:
    """An MLP (:func:`mlp_layers`) whose weights are views of a flat vector, with its forward and backward passes.

    :param layers: the MLP's layers
    :param adam: the flat optimizer over exactly the layers' weights and biases
    """

    def __init__(self, layers: list[Layer], adam: FlatAdam) -> None:
        index = {id(parameter): i for i, parameter in enumerate(adam.parameters)}
        if sorted(index) != sorted(id(p) for linear, _ in layers for p in (linear.weight, linear.bias)):
            raise ValueError("FlatMlp: the optimizer's parameters must be exactly the layers' weights and biases")
        values, grads = adam.views(adam.vector), adam.views(adam.grad)
        self.weights = [(values[index[id(linear.weight)]], values[index[id(linear.bias)]]) for linear, _ in layers]
        self.grads = [(grads[index[id(linear.weight)]], grads[index[id(linear.bias)]]) for linear, _ in layers]
        self.activations = [None if activation is None else ACTIVATIONS[activation] for _, activation in layers]

    def forward(self, inputs: th.Tensor) -> list[th.Tensor]:
        """Each layer's output (after its activation) for ``inputs``, ``inputs`` first and the MLP's output last."""
        outputs = [inputs]
        for (weight, bias), activation in zip(self.weights, self.activations, strict=True):
            output = th.addmm(bias, outputs[-1], weight.t())
            outputs.append(output if activation is None else activation[0](output))
        return outputs

    def backward(self, outputs: list[th.Tensor], grad: th.Tensor) -> None:
        """Write the gradient of the loss into the flat optimizer's ``grad``, given ``grad``, its gradient with
        respect to the MLP's output, and ``outputs`` from :meth:`forward` (no gradient flows into the inputs)."""
        for layer in reversed(range(len(self.weights))):
            activation = self.activations[layer]
            if activation is not None:
                grad = activation[1](grad, outputs[layer + 1])
            grad_weight, grad_bias = self.grads[layer]
            th.mm(grad.t(), outputs[layer], out=grad_weight)
            th.sum(grad, 0, out=grad_bias)
            if layer:
                grad = th.mm(grad, self.weights[layer][0])


def mean_backward_scale(numel: int, like: th.Tensor) -> th.Tensor:
    """``1 / numel`` as autograd's backward of a mean computes it: a division in the tensor's dtype."""
    return th.ones((), dtype=like.dtype, device=like.device) / numel
