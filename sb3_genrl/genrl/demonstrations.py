"""GenRL that learns from demonstrations: the policy's mean fitted to them before the first iteration, and the
demonstrations kept among the hindsight relabelling's pulls for the whole run.

A demonstration is a trajectory ``tau`` that solves a context (:func:`demonstration_contexts`): the one it starts
from where its first observation, ``observations[:, 0]``, is a context (the Fetch tasks, Meta-World: the state with the
goal it reached, as ``genrl demos`` stores it), else the goal it reached (``reached``: hockey's and basketball's context
is the goal, and a demonstration solves the point it reached, as the hindsight relabelling labels a pull). Its latent
action is the generator's posterior mean ``alpha = E[q(alpha | tau)]`` (a beta-VAE's encoder), clipped to GenRL's
``latent_clip``, so each demonstration is a pull ``(context, alpha, reward 0)`` that needs no simulation.
:class:`DemonstrationCallback` uses them in two ways, both switched by its arguments:

- ``fit_steps``: before the first iteration of a fresh run, the policy's mean is fitted to the pairs by the regression
  of the hindsight component (:func:`~sb3_genrl.genrl.regression.regress_mean`), so that GenRL starts where the
  demonstrations are (as behaviour cloning starts PPO); a resumed run is not fitted again;
- ``keep``: the pulls are kept for the whole run (GenRL's :class:`~sb3_genrl.genrl.kept_pulls.KeptPulls`), beside the
  relabelled pulls of the last ``history`` batches of :class:`~sb3_genrl.genrl.hindsight.HindsightRelabelling`: they
  join every E-step's batch and every regression of the mean, as demonstrations stay in SAC+HER's replay buffer;
- ``refit``: the pairs join every refit of the mean to the run's solving pulls (GenRL's
  :class:`~sb3_genrl.genrl.refits.Refits`, ``hindsight_kwargs["refit_every"]``), so that a refit made while the run has
  found few solving pulls still covers the contexts the demonstrations solve.

The callback is an SB3 callback, given to ``learn`` or named in a task's entry of ``hyperparams/genrl.yml`` in
rl-zoo3's ``callback`` form (see :func:`build_callbacks`)::

    callback:
      - sb3_genrl.genrl.demonstrations.DemonstrationCallback: {fit_steps: 4000, keep: true}

where ``genrl train-policy --data``, ``genrl quickstart`` and the rl-zoo3 runs fill in the dataset.
"""

from __future__ import annotations

import importlib
import inspect
import os
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import ActorCriticPolicy

from sb3_genrl.data import load_arrays
from sb3_genrl.data.fingerprints import dataset_fingerprint as fingerprint
from sb3_genrl.genrl.policies import scale_contexts
from sb3_genrl.genrl.regression import fit_mean

DEMONSTRATION_CALLBACK = "sb3_genrl.genrl.demonstrations.DemonstrationCallback"
NO_DATASET = (
    "learn from demonstrations (the callback {name}) and need their dataset: give it "
    "(train_policy(..., demonstrations=DIR), genrl train-policy --data DIR), the dataset the generator was "
    "trained on, or one made by `genrl demos --task {task} --episodes 4000 --out DIR`"
)


class DemonstrationCallback(BaseCallback):
    """Start GenRL from demonstrations and keep them among its hindsight pulls (see the module doc).

    :param dataset: a demonstration dataset folder (as ``genrl demos`` writes it, read by
        :func:`sb3_genrl.data.load_arrays`); ``None`` only in a settings file, where the entry point fills it in
    :param fit_steps: Adam steps fitting the policy's mean to the demonstrations before the first iteration of a fresh
        run (default 4000; 0: no fit)
    :param keep: keep the demonstrations among the hindsight relabelling's pulls for the whole run (default True;
        needs GenRL's ``hindsight_kwargs``)
    :param refit: the demonstrations join the pairs of every refit of the mean (default False; needs
        ``hindsight_kwargs["refit_every"]``)
    :param learning_rate: Adam learning rate of the fit (default 1e-3)
    :param batch_size: demonstrations per step of the fit, drawn with replacement (default 256)
    :param scale_contexts: on a fresh run, before the fit, centre and scale each unbounded dimension of the policy's
        context features by the demonstrations' contexts (:meth:`~sb3_genrl.genrl.policies.BoxScaler.scale_unbounded`;
        saved with the policy). Default False: unbounded dimensions pass unscaled
    :param dataset_fingerprint: the dataset's :func:`~sb3_genrl.data.fingerprints.dataset_fingerprint`, when known (a saved
        run records it): a dataset whose content differs is refused
    :param verbose: 1: print the fit's losses
    """

    def __init__(
        self,
        dataset: str | os.PathLike | None = None,
        *,
        fit_steps: int = 4000,
        keep: bool = True,
        refit: bool = False,
        learning_rate: float = 1e-3,
        batch_size: int = 256,
        scale_contexts: bool = False,
        dataset_fingerprint: str | None = None,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        check_demonstration_settings(
            fit_steps=fit_steps,
            keep=keep,
            refit=refit,
            learning_rate=learning_rate,
            batch_size=batch_size,
            scale_contexts=scale_contexts,
        )
        if dataset is None:
            raise ValueError(
                "DemonstrationCallback(dataset=None): settings that "
                + NO_DATASET.format(name=DEMONSTRATION_CALLBACK, task="TASK")
            )

        self.dataset, self.fit_steps, self.keep, self.refit = os.fspath(dataset), int(fit_steps), bool(keep), bool(refit)
        self.learning_rate, self.batch_size = float(learning_rate), int(batch_size)
        self.scale_contexts = bool(scale_contexts)
        arrays = load_arrays(self.dataset, keys=("observations", "actions", "reached"))  # raises naming a missing dataset
        if dataset_fingerprint is not None:
            if fingerprint(self.dataset) != dataset_fingerprint:
                raise ValueError(
                    f"the demonstrations {self.dataset} are not the ones this run was trained with "
                    f"(fingerprint {dataset_fingerprint}): they were changed or made again"
                )
        self.first_observations, self.reached = arrays["observations"][:, 0], arrays["reached"]
        self.actions = arrays["actions"]
        self.fit: dict[str, float] = {}  # the fit's demonstrations, steps and losses, once it has run

    def pulls(self, generator: Any, context_space: spaces.Space, latent_clip: float) -> tuple[th.Tensor, th.Tensor]:
        """The demonstrations as pulls: their contexts and latent actions (float32), checked against the generator and
        the env's context space; raises ``ValueError`` naming what does not fit."""
        name = f"demonstrations {self.dataset}"
        if generator is None or not callable(getattr(generator, "encode", None)):
            raise ValueError(
                f"{name}: their latent actions are the generator's posterior means, which needs a generator "
                f"with an encoder (a beta-VAE); got {type(generator).__name__}"
            )
        shape = (generator.horizon, generator.action_dim)
        if self.actions.shape[1:] != shape:
            raise ValueError(
                f"{name}: trajectories of shape {self.actions.shape[1:]} (steps, action dimension), but the "
                f"generator makes {shape}: the dataset of another task, or a generator trained on other data"
            )
        contexts, rows = demonstration_contexts(self.first_observations, self.reached, context_space, name)
        latents = np.clip(generator.encode(self.actions[rows])[0], -latent_clip, latent_clip)
        return th.as_tensor(contexts, dtype=th.float32), th.as_tensor(latents, dtype=th.float32)

    def check(
        self,
        generator: Any,
        context_space: spaces.Space,
        latent_clip: float,
        hindsight: bool,
        refits: bool = False,
    ) -> tuple[th.Tensor, th.Tensor]:
        """:meth:`pulls`, refused (before any work) also for ``keep`` without GenRL's hindsight relabelling, and for
        ``refit`` without its refits (``refits``: GenRL's ``hindsight_kwargs["refit_every"]`` is set)."""
        if self.keep and not hindsight:
            raise ValueError(
                "DemonstrationCallback(keep=True) keeps the demonstrations among the hindsight "
                "relabelling's pulls, which needs GenRL's hindsight_kwargs (or keep=False)"
            )
        if self.refit and not refits:
            raise ValueError(
                "DemonstrationCallback(refit=True) adds the demonstrations to the refits of the mean, which need "
                "GenRL's hindsight_kwargs['refit_every'] (or refit=False)"
            )
        return self.pulls(generator, context_space, latent_clip)

    def _on_training_start(self) -> None:
        model = self.model
        contexts, latents = (
            tensor.to(model.device)
            for tensor in self.check(
                model.generator,
                model.observation_space,
                model.latent_clip,
                model.kept_pulls is not None,
                model.refits is not None,
            )
        )
        fresh = model.num_timesteps == 0 and model._n_updates == 0  # never a resumed run, whose policy holds both
        if self.scale_contexts and fresh:
            scale_contexts(model.policy, contexts)
        if self.fit_steps and fresh:
            self.fit = fit_mean_to_demonstrations(
                model.policy,
                contexts,
                latents,
                steps=self.fit_steps,
                learning_rate=self.learning_rate,
                batch_size=self.batch_size,
            )
            for key, value in self.fit.items():
                self.logger.record(f"demonstrations/{key}", value)
            if self.verbose:
                print(
                    f"policy mean fitted to {self.fit['demonstrations']} demonstrations: loss "
                    f"{self.fit['first_loss']:.4g} -> {self.fit['last_loss']:.4g}"
                )
        if (self.fit_steps or self.scale_contexts) and fresh and model.policy_average is not None:
            model.policy_average.load_state_dict(model.policy.state_dict())  # the average starts from this policy too
        if self.keep and model.kept_pulls.pulls is None:  # (a resumed run's checkpoint holds them already)
            model.kept_pulls.keep(contexts, latents, th.zeros(len(latents), device=model.device))
        if self.refit:  # (handed over at every start, a resumed run's too: the checkpoint holds the solving pulls alone)
            model.refits.demonstrations = (contexts, latents)

    def _on_step(self) -> bool:
        return True


def demonstration_contexts(
    first_observations: np.ndarray, reached: np.ndarray, context_space: spaces.Space, name: str = "demonstrations"
) -> tuple[np.ndarray, np.ndarray]:
    """The contexts the demonstrations solve, and the indices of the demonstrations they are of.

    Each demonstration's first observation where it has the context space's shape (a task whose observation is its
    context: the Fetch tasks, Meta-World); else the point it reached where that has the context's shape (a task
    whose context is the goal alone: hockey, basketball), the demonstrations without one (``nan``) left out.

    :param first_observations: ``observations[:, 0]`` of the dataset
    :param reached: the dataset's ``reached`` points (``nan`` where it records none)
    :param context_space: the env's context (observation) space
    :param name: what the demonstrations are, for the error message
    :raises ValueError: when neither is a context of ``context_space``, or no demonstration reached a point
    """
    if isinstance(context_space, spaces.Box):
        if first_observations.shape[1:] == context_space.shape:
            return first_observations, np.arange(len(first_observations))
        if reached.shape[1:] == context_space.shape:
            rows = np.flatnonzero(np.isfinite(reached).all(axis=tuple(range(1, reached.ndim))))
            if len(rows) == 0:
                raise ValueError(f"{name}: none records the point it reached, which would be its context")
            return reached[rows], rows
    if not isinstance(context_space, spaces.Box):
        raise ValueError(
            f"{name}: demonstrations start GenRL on a Box context (a flat observation or goal), but the env's context "
            f"space is {context_space}; leave the demonstrations out (GenRL searches from its prior), or give the env "
            "a Box observation (e.g. gymnasium.wrappers.FlattenObservation)"
        )
    raise ValueError(
        f"{name}: a demonstration's context is its first observation, of shape {first_observations.shape[1:]}, or "
        f"else the point it reached, of shape {reached.shape[1:]}, but the env's context space is {context_space}: the "
        "demonstrations of another task"
    )


def fit_mean_to_demonstrations(
    policy: ActorCriticPolicy,
    contexts: th.Tensor,
    latents: th.Tensor,
    *,
    steps: int,
    learning_rate: float = 1e-3,
    batch_size: int = 256,
) -> dict[str, float]:
    """Fit the policy's mean to ``latents`` at ``contexts`` by ``steps`` steps of a new Adam over its mean's
    parameters (:func:`~sb3_genrl.genrl.regression.fit_mean`), in training mode.

    :return: ``demonstrations`` (pairs), ``steps``, ``first_loss`` (the first minibatch's mean squared error) and
        ``last_loss`` (the mean of the last 100 minibatches')
    """
    losses = fit_mean(policy, contexts, latents, steps=steps, learning_rate=learning_rate, batch_size=batch_size)
    return {
        "demonstrations": len(latents),
        "steps": int(steps),
        "first_loss": float(losses[0]),
        "last_loss": float(np.mean(losses[-100:])),
    }


def check_demonstration_settings(
    *, fit_steps: Any, keep: Any, learning_rate: Any, batch_size: Any, scale_contexts: Any = False, refit: Any = False
) -> None:
    """Refuse settings :class:`DemonstrationCallback` would not take, naming the setting."""
    for key, value, minimum in (("fit_steps", fit_steps, 0), ("batch_size", batch_size, 1)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
            raise ValueError(f"DemonstrationCallback: {key} must be an integer >= {minimum}, got {value!r}")
    for key, value in (("keep", keep), ("scale_contexts", scale_contexts), ("refit", refit)):
        if not isinstance(value, bool | np.bool_):
            raise ValueError(f"DemonstrationCallback: {key} must be True or False, got {value!r}")
    if isinstance(learning_rate, bool) or not isinstance(learning_rate, int | float) or not learning_rate > 0:
        raise ValueError(f"DemonstrationCallback: learning_rate must be positive, got {learning_rate!r}")
    if not fit_steps and not keep and not refit:
        raise ValueError("DemonstrationCallback with fit_steps=0, keep=False and refit=False would not use the demonstrations")


def callback_entries(spec: Any, name: str = "callback") -> list[tuple[str, dict[str, Any]]]:
    """rl-zoo3's ``callback`` setting as ``(class path, arguments)`` pairs: a class path, ``{path: {arguments}}``, or a
    list of them (``None``: none); the arguments of :class:`DemonstrationCallback` are checked."""
    if spec is None:
        return []
    entries = []
    for item in spec if isinstance(spec, list) else [spec]:
        if isinstance(item, str):
            path, kwargs = item, {}
        elif isinstance(item, dict) and len(item) == 1 and isinstance(next(iter(item)), str):
            path, kwargs = next(iter(item.items()))
            kwargs = {} if kwargs is None else kwargs
        else:
            raise ValueError(f"{name}: expected a callback class path or {{path: {{arguments}}}}, got {item!r}")
        if not isinstance(kwargs, dict):
            raise ValueError(f"{name}: the arguments of {path} must be a mapping, got {kwargs!r}")
        if path == DEMONSTRATION_CALLBACK:
            parameters = inspect.signature(DemonstrationCallback.__init__).parameters
            unknown = sorted(set(kwargs) - (set(parameters) - {"self"}))
            if unknown:
                raise ValueError(
                    f"{name}: {', '.join(map(repr, unknown))} not among DemonstrationCallback's arguments "
                    f"({', '.join(key for key in parameters if key != 'self')})"
                )
            check_demonstration_settings(
                **{
                    key: kwargs.get(key, parameters[key].default)
                    for key in ("fit_steps", "keep", "refit", "learning_rate", "batch_size", "scale_contexts")
                }
            )
        entries.append((path, dict(kwargs)))
    return entries


def uses_demonstrations(spec: Any) -> bool:
    """Whether rl-zoo3's ``callback`` setting ``spec`` holds a :class:`DemonstrationCallback`."""
    return any(path == DEMONSTRATION_CALLBACK for path, _ in callback_entries(spec))


def with_dataset(spec: Any, dataset: str | os.PathLike, fingerprint: str | None = None) -> list[dict[str, Any]]:
    """``spec`` (rl-zoo3's ``callback`` setting) as a list of ``{path: {arguments}}``, its
    :class:`DemonstrationCallback` given ``dataset`` (and ``dataset_fingerprint``) where it names none."""
    filled = []
    for path, kwargs in callback_entries(spec):
        if path == DEMONSTRATION_CALLBACK and kwargs.get("dataset") is None:
            kwargs = {**kwargs, "dataset": os.fspath(dataset)} | (
                {} if fingerprint is None else {"dataset_fingerprint": fingerprint}
            )
        filled.append({path: kwargs})
    return filled


def build_callbacks(
    spec: Any, *, demonstrations: str | os.PathLike | None = None, what: str = "these settings", task: str = "TASK"
) -> list[BaseCallback]:
    """The callbacks of rl-zoo3's ``callback`` setting ``spec`` (as rl-zoo3 builds them), a
    :class:`DemonstrationCallback` without a dataset given ``demonstrations``.

    :param spec: a class path, ``{path: {arguments}}`` or a list of them (``None``: no callbacks)
    :param demonstrations: the dataset of a :class:`DemonstrationCallback` that names none
    :param what: what the settings are, for the error messages (``"the settings of fetch-push"``)
    :param task: the task's name, for the error messages
    :raises ValueError: a :class:`DemonstrationCallback` without a dataset and no ``demonstrations``, or
        ``demonstrations`` given to settings without one
    """
    if demonstrations is not None:
        if not uses_demonstrations(spec):
            raise ValueError(
                f"demonstrations {os.fspath(demonstrations)!r} given, but {what} do not learn from "
                f"demonstrations: add the callback {DEMONSTRATION_CALLBACK} to them"
            )
        spec = with_dataset(spec, demonstrations)
    callbacks = []
    for path, kwargs in callback_entries(spec):
        if path == DEMONSTRATION_CALLBACK and kwargs.get("dataset") is None:
            raise ValueError(f"{what} " + NO_DATASET.format(name=DEMONSTRATION_CALLBACK, task=task))
        callbacks.append(callback_class(path, what)(**kwargs))
    return callbacks


def callback_class(path: str, what: str = "these settings") -> type:
    """The class a callback setting names by its path (``sb3_genrl.genrl.demonstrations.DemonstrationCallback``)."""
    module, _, name = path.rpartition(".")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError, ValueError) as error:
        raise ValueError(f"{what}: no callback class {path!r} ({error})") from None
