"""Base class of the neural generators: normalisation, decoding, the epoch loop with model selection, saving.

A subclass (:class:`~sb3_genrl.generative.BetaVAE`, :class:`~sb3_genrl.generative.InfoGAN`) only says what is specific
to it: its networks, its optimizers, one gradient step and its hyperparameters.
"""

from __future__ import annotations

import abc
import math
from collections import defaultdict
from typing import Any, TypeVar

import numpy as np
import torch
from stable_baselines3.common.utils import get_device
from torch import nn
from tqdm.auto import tqdm

from sb3_genrl.checks import check_int
from sb3_genrl.generative.base import Prior, TrajectoryGenerator
from sb3_genrl.generative.common import (
    STD_FLOOR,
    check_trajectories,
    minibatch_indices,
    normalisation_statistics,
    selection_mse,
    split_train_validation,
)
from sb3_genrl.generative.defaults import BATCH_SIZE, EPOCHS, LEARNING_RATE, SELECTION_SAMPLES
from sb3_genrl.generative.file_format import save_generator

# How :meth:`TorchTrajectoryGenerator.fit` chooses the checkpoint it keeps: "prior", paper appendix B's (trajectories
# generated from fixed prior draws against their nearest held-out ones), or "reconstruction" (the held-out trajectories
# decoded from their posterior means, a model with an encoder's: what GenRL's fit to the demonstrations starts from).
SELECTIONS = ("prior", "reconstruction")

SelfTorchTrajectoryGenerator = TypeVar("SelfTorchTrajectoryGenerator", bound="TorchTrajectoryGenerator")


def check_selection(model: type | object, selection: str) -> None:
    """Refuse a checkpoint selection that is not one of :data:`SELECTIONS`, or ``"reconstruction"`` for a model
    (class or instance) without an encoder."""
    if selection not in SELECTIONS:
        raise ValueError(f"selection must be one of {SELECTIONS}, got {selection!r}")
    if selection == "reconstruction" and not model.has_encoder:  # type: ignore[union-attr]
        name = model.__name__ if isinstance(model, type) else type(model).__name__
        raise ValueError(f"selection='reconstruction' needs a model with an encoder (a VAE); {name} has none: use 'prior'")


def _summary_writer(log_dir: str | None) -> Any:
    """A TensorBoard ``SummaryWriter`` writing to ``log_dir``, or ``None`` when ``log_dir`` is ``None``."""
    if log_dir is None:
        return None
    from torch.utils.tensorboard import SummaryWriter

    return SummaryWriter(log_dir=log_dir)


class TorchTrajectoryGenerator(TrajectoryGenerator, abc.ABC):
    """A neural trajectory generator whose decoder maps ``alpha`` to a normalised, flattened trajectory.

    Training data are normalised entry by entry (a mean and a standard deviation per time step and joint over the
    training split, see :func:`~sb3_genrl.generative.common.normalisation_statistics`); the statistics are part
    of the model and :meth:`decode` returns raw action units.

    ``std_floor`` bounds every entry's std from below by that fraction of the largest entry's std. Without it, an
    entry that hardly varies in the demonstrations (a joint held still but for small perturbations) weighs, once
    normalised, as much as the motion that matters, and a low-dimensional latent space spends itself on the
    perturbations (as in the hockey demonstrations, where two joints move and the other five are only perturbed).

    :param horizon: number of time steps ``T``
    :param action_dim: number of joints ``M``
    :param latent_dim: ``N_alpha``
    :param prior: ``"normal"`` or ``"uniform"``
    :param std_floor: floor of each entry's normalisation std, as a fraction of the largest entry's (default
        :data:`~sb3_genrl.generative.common.STD_FLOOR`, 0.05)
    :param device: torch device or ``"auto"`` (CUDA when available), as in Stable-Baselines3
    """

    decoder_name: str = "decoder"
    has_encoder = False  # whether reconstruction_mse (and fit's selection="reconstruction") is available

    def __init__(
        self,
        *,
        horizon: int,
        action_dim: int,
        latent_dim: int,
        prior: Prior,
        std_floor: float = STD_FLOOR,
        device: torch.device | str = "auto",
    ) -> None:
        super().__init__(horizon=horizon, action_dim=action_dim, latent_dim=latent_dim, prior=prior)
        if not 0.0 <= std_floor <= 1.0:
            raise ValueError(f"std_floor must be in [0, 1] (a fraction of the largest std), got {std_floor!r}")
        self.std_floor = float(std_floor)
        self.networks: nn.ModuleDict
        self._reset(0, device)  # untrained weights from seed 0; fit() draws them again from its own seed
        self.action_mean = torch.zeros(self.horizon, self.action_dim, device=self.device)
        self.action_std = torch.ones(self.horizon, self.action_dim, device=self.device)
        self.history: list[dict[str, float]] = []
        self.best_epoch: int | None = None
        self.selection = "prior"  # the checkpoint's selection (SELECTIONS) of the last fit
        self.seed: int | None = None
        self.saved_version: str | None = None  # sb3-genrl version that wrote the file this model was loaded from

    # --- what a subclass provides -----------------------------------------------------------------------------------
    @abc.abstractmethod
    def _build_networks(self) -> nn.ModuleDict:
        """All networks of the model; ``self.decoder_name`` names the one :meth:`decode` uses."""

    @abc.abstractmethod
    def _make_optimizers(self, lr: float) -> list[torch.optim.Optimizer]:
        """Fresh optimizers for one call to :meth:`fit`. The models' Adams take torch's multi-tensor ("foreach")
        steps, as on a GPU by default: on a CPU (where the default is one parameter at a time) the same values, a
        step's update about a quarter cheaper (``tests/test_generative.py`` compares the weights bit for bit)."""

    @abc.abstractmethod
    def _train_step(
        self, batch: torch.Tensor, optimizers: list[torch.optim.Optimizer], generator: torch.Generator
    ) -> dict[str, float]:
        """One gradient step on a normalised, flattened ``(B, T*M)`` batch; returns the losses to log."""

    @abc.abstractmethod
    def _hyperparameters(self) -> dict[str, Any]:
        """Constructor keyword arguments beyond the shapes (JSON-able), saved with the model."""

    def _decoder_input(self, alpha: torch.Tensor) -> torch.Tensor:
        """What the decoder receives at decoding time for latent actions ``alpha`` (by default ``alpha`` itself)."""
        return alpha

    # --- decoding ---------------------------------------------------------------------------------------------------
    @property
    def decoder(self) -> nn.Module:
        return self.networks[self.decoder_name]

    def config(self) -> dict[str, Any]:
        """Constructor arguments that rebuild this model (without the device)."""
        return {
            "horizon": self.horizon,
            "action_dim": self.action_dim,
            "latent_dim": self.latent_dim,
            "std_floor": self.std_floor,
            **self._hyperparameters(),
        }

    def normalise(self, trajectories: torch.Tensor) -> torch.Tensor:
        """Raw ``(n, T, M)`` trajectories -> what the networks see, normalised and flattened ``(n, T*M)``."""
        return ((trajectories - self.action_mean) / self.action_std).flatten(1)

    def denormalise(self, normalised: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`normalise`: normalised, flattened ``(n, T*M)`` -> raw ``(n, T, M)`` trajectories."""
        return normalised.view(-1, self.horizon, self.action_dim) * self.action_std + self.action_mean

    def decode_torch(self, alpha: torch.Tensor) -> torch.Tensor:
        """Differentiable decoding of a ``(n, latent_dim)`` tensor into ``(n, T, M)`` raw actions on ``self.device``.

        Uses the decoder in evaluation mode (batch-norm running statistics), so the output is deterministic.
        """
        if alpha.ndim != 2 or alpha.shape[1] != self.latent_dim:
            raise ValueError(f"latent actions must have shape (n, {self.latent_dim}), got {tuple(alpha.shape)}")
        if not bool(torch.isfinite(alpha).all()):
            raise ValueError("latent actions contain non-finite values (nan or inf)")
        self.networks.eval()
        return self.denormalise(self.decoder(self._decoder_input(alpha.to(self.device, torch.float32))))

    def decode(self, alpha: np.ndarray) -> np.ndarray:
        """Map latent actions ``(n, latent_dim)`` to float32 trajectories ``(n, T, M)`` in raw action units (CPU)."""
        alpha = self.check_latent(alpha)
        with torch.no_grad():
            return self.decode_torch(torch.as_tensor(alpha)).cpu().numpy().astype(np.float32, copy=False)

    # --- training ---------------------------------------------------------------------------------------------------
    def fit(
        self: SelfTorchTrajectoryGenerator,
        trajectories: np.ndarray,
        *,
        epochs: int = EPOCHS,
        batch_size: int = BATCH_SIZE,
        lr: float = LEARNING_RATE,
        seed: int | None = None,
        validation_fraction: float = 0.1,
        tensorboard_log: str | None = None,
        progress_bar: bool = True,
        device: torch.device | str | None = None,
        selection_samples: int = SELECTION_SAMPLES,
        eval_every: int = 10,
        selection: str = "prior",
        min_steps: int = 0,
        even_batches: bool = False,
    ) -> SelfTorchTrajectoryGenerator:
        """Train from a fresh initialisation drawn from ``seed`` and keep the best checkpoint (paper appendix B).

        Every ``eval_every`` epochs (and after the last one) the model is scored on the held-out trajectories, and the
        weights with the lowest error are restored at the end. With ``selection="prior"`` (paper appendix B)
        ``selection_samples`` trajectories generated from a fixed set of prior samples are compared with the held-out
        trajectories by :func:`selection_mse`; with ``selection="reconstruction"`` (a model with an encoder) the error
        is that of the held-out trajectories decoded from their posterior means (:meth:`reconstruction_mse`). Without a
        held-out split the last weights are kept.

        :param trajectories: ``(N, T, M)`` demonstrations in raw action units
        :param epochs: passes over the training split (paper: 5000)
        :param batch_size: minibatch size (paper: 256)
        :param lr: Adam learning rate (paper: 2e-4)
        :param seed: seed of the split, the initial weights, the minibatches and the latent noise; ``None`` draws one
        :param validation_fraction: fraction of the trajectories held out for model selection
        :param tensorboard_log: directory for TensorBoard scalars (``train/*`` per epoch, ``eval/selection_mse``)
        :param progress_bar: show a tqdm progress bar over epochs
        :param device: torch device or ``"auto"``; ``None`` (default) keeps the device the model was built on
        :param selection_samples: generated trajectories per model-selection evaluation (paper: 100)
        :param eval_every: epochs between model-selection evaluations
        :param selection: how the checkpoint is chosen, one of :data:`SELECTIONS` (default ``"prior"``, the paper's)
        :param min_steps: at least this many minibatch steps: on a dataset too small for ``epochs`` to reach them, the
            epochs are raised until they do (default 0: ``epochs`` as given)
        :param even_batches: split each epoch into minibatches of nearly equal sizes (at most ``batch_size``) instead
            of full ones and a remainder, which can be a handful of trajectories (a step on a few trajectories weighs
            as much as one on a full batch, and batch normalisation's statistics of those few are noisy)
        :return: this model, trained; per evaluation ``self.history`` holds the epoch, its mean losses and the
            selection MSE (the selection's error, in squared raw action units), and ``self.best_epoch`` the restored
            epoch
        """
        data = check_trajectories(trajectories, self.horizon, self.action_dim)
        for name, value in (("epochs", epochs), ("selection_samples", selection_samples), ("eval_every", eval_every)):
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        check_selection(self, selection)
        check_int(min_steps, "min_steps", minimum=0)
        if not 0 < lr < math.inf:
            raise ValueError(f"lr must be positive and finite, got {lr}")
        self.seed = int(np.random.default_rng().integers(2**31)) if seed is None else int(seed)
        rng = np.random.default_rng(self.seed)
        train, held_out = split_train_validation(data, validation_fraction, rng)
        # validates batch_size early
        batches = len(minibatch_indices(len(train), batch_size, np.arange(len(train)), even=even_batches))
        epochs = max(int(epochs), math.ceil(int(min_steps) / max(batches, 1)))
        self.selection = selection

        self._reset(self.seed, self.device if device is None else device)
        mean, std = normalisation_statistics(train, std_floor=self.std_floor)
        self.action_mean = torch.as_tensor(mean, device=self.device)
        self.action_std = torch.as_tensor(std, device=self.device)
        train_tensor = self.normalise(torch.as_tensor(train, device=self.device))
        optimizers = self._make_optimizers(lr)
        noise_generator = torch.Generator().manual_seed(self.seed)
        selection_latents = self.sample_prior(selection_samples, rng)
        writer = _summary_writer(tensorboard_log)
        try:
            best_state = self._train_epochs(
                train_tensor,
                held_out,
                selection_latents,
                optimizers,
                rng,
                noise_generator,
                epochs=epochs,
                batch_size=batch_size,
                even_batches=bool(even_batches),
                eval_every=eval_every,
                progress_bar=progress_bar,
                writer=writer,
            )
        finally:
            if writer is not None:
                writer.close()
        if best_state is not None:
            self.networks.load_state_dict(best_state)
        self.networks.eval()
        return self

    def _train_epochs(
        self,
        train: torch.Tensor,
        held_out: np.ndarray,
        selection_latents: np.ndarray,
        optimizers: list[torch.optim.Optimizer],
        rng: np.random.Generator,
        noise_generator: torch.Generator,
        *,
        epochs: int,
        batch_size: int,
        even_batches: bool,
        eval_every: int,
        progress_bar: bool,
        writer: Any,
    ) -> dict[str, torch.Tensor] | None:
        """The epoch loop of :meth:`fit`, filling ``self.history`` and ``self.best_epoch``; returns the best weights."""
        self.history, self.best_epoch = [], None
        best_error, best_state = math.inf, None
        for epoch in tqdm(range(1, epochs + 1), disable=not progress_bar, desc=type(self).__name__, unit="epoch"):
            losses = self._train_epoch(train, batch_size, optimizers, rng, noise_generator, even_batches)
            if writer is not None:
                for name, value in losses.items():
                    writer.add_scalar(f"train/{name}", value, epoch)
            if epoch % eval_every != 0 and epoch != epochs:
                continue
            error = self._selection_error(selection_latents, held_out) if len(held_out) else math.nan
            self.history.append({"epoch": epoch, **losses, "selection_mse": error})
            if writer is not None and len(held_out):
                writer.add_scalar("eval/selection_mse", error, epoch)
            if not len(held_out) or error < best_error:
                best_error, self.best_epoch = error, epoch
                best_state = {key: value.detach().clone() for key, value in self.networks.state_dict().items()}
        return best_state

    def _selection_error(self, selection_latents: np.ndarray, held_out: np.ndarray) -> float:
        """The error :meth:`fit` selects the checkpoint by (:attr:`selection`), in squared raw action units."""
        if self.selection == "reconstruction":
            return self.reconstruction_mse(held_out)
        return selection_mse(self.decode(selection_latents), held_out)

    def reconstruction_mse(self, trajectories: np.ndarray) -> float:
        """Mean squared error, per element in raw action units, of raw ``(n, T, M)`` trajectories decoded from their
        posterior means; only a model with an encoder has one."""
        raise NotImplementedError(f"{type(self).__name__} has no encoder: no reconstruction error")

    def _reset(self, seed: int, device: torch.device | str) -> None:
        """Rebuild the networks on ``device`` with initial weights drawn from ``seed`` (global torch RNG untouched)."""
        self.device = get_device(device)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.networks = self._build_networks().to(self.device)

    def _train_epoch(
        self,
        train: torch.Tensor,
        batch_size: int,
        optimizers: list[torch.optim.Optimizer],
        rng: np.random.Generator,
        noise_generator: torch.Generator,
        even_batches: bool = False,
    ) -> dict[str, float]:
        """One pass over the shuffled training split (:func:`minibatch_indices`); returns the losses averaged over its
        samples."""
        self.networks.train()
        sums: dict[str, float] = defaultdict(float)
        count = 0
        for indices in minibatch_indices(len(train), batch_size, rng.permutation(len(train)), even=even_batches):
            batch = train[torch.as_tensor(indices, device=self.device)]
            for name, value in self._train_step(batch, optimizers, noise_generator).items():
                sums[name] += value * len(indices)
            count += len(indices)
        return {name: total / count for name, total in sums.items()}

    def _noise(self, kind: Prior, shape: tuple[int, ...], generator: torch.Generator) -> torch.Tensor:
        """Standard normal or U(-1, 1) noise drawn on the CPU from ``generator`` (device-independent), on the device."""
        if kind == "normal":
            noise = torch.randn(shape, generator=generator)
        else:
            noise = torch.rand(shape, generator=generator) * 2.0 - 1.0
        return noise.to(self.device)

    # --- saving -----------------------------------------------------------------------------------------------------
    def state_tensors(self) -> dict[str, torch.Tensor]:
        """All weights and the normalisation statistics, as CPU tensors."""
        state = {f"networks.{key}": value.detach().cpu() for key, value in self.networks.state_dict().items()}
        state["action_mean"] = self.action_mean.detach().cpu()
        state["action_std"] = self.action_std.detach().cpu()
        return state

    def load_state_tensors(self, state: dict[str, torch.Tensor]) -> None:
        """Inverse of :meth:`state_tensors`; raises ``ValueError`` on missing, unexpected or misshaped entries."""
        state = dict(state)
        try:
            mean, std = state.pop("action_mean"), state.pop("action_std")
        except KeyError as error:
            raise ValueError(f"missing normalisation statistics {error}") from None
        expected = (self.horizon, self.action_dim)
        if tuple(mean.shape) != expected or tuple(std.shape) != expected:
            raise ValueError(
                f"normalisation statistics must have shape {expected}, got {tuple(mean.shape)} and {tuple(std.shape)}"
            )
        prefix = "networks."
        networks_state = {key[len(prefix) :]: value for key, value in state.items() if key.startswith(prefix)}
        if len(networks_state) != len(state):
            raise ValueError(f"unexpected entries {sorted(set(state) - {prefix + key for key in networks_state})}")
        try:
            self.networks.load_state_dict(networks_state)
        except RuntimeError as error:
            raise ValueError(f"weights do not match the architecture: {error}") from None
        self.action_mean = mean.to(self.device, torch.float32)
        self.action_std = std.to(self.device, torch.float32)
        self.networks.eval()

    def save(self, path: str) -> None:
        """Write weights, configuration, normalisation statistics, history and package version to one file."""
        save_generator(self, path)
