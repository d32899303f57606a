"""Two fixed-seed GenRL runs on the toy tasks whose saved parameters are kept in ``data/reference_parameters.npz``, so
that a change meant to leave the numbers alone is checked bit for bit (tests/genrl/test_reference_runs.py).

- ``hindsight``: three envs on the batched VecEnv, hindsight with a history of three batches, the weighted regression of
  the mean, a value history and a policy average;
- ``refits_demonstrations``: two envs on SB3's DummyVecEnv, pulls that report their success, hindsight with refits of
  the mean to the solving pulls, and demonstrations fitted before the first iteration and kept among the pulls.

Run ``python tests/genrl/reference_runs.py`` to write the file again, only when a change is meant to change the
numbers (with one torch thread, as the tests run). The file records the machine that wrote it (:func:`machine`): float
kernels differ in their last bits from one CPU to another, so only that machine can expect the same bits.
"""

from __future__ import annotations

import hashlib
import pathlib
import platform
import sys
import tempfile

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.vec_env import DummyVecEnv

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # tests/, for conftest when run as a script
from conftest import C, LinearGenerator, R  # noqa: E402
from genrl_test_helpers import HindsightReachEnv, SuccessReachEnv  # noqa: E402

from sb3_genrl import GenRL, LatentActionWrapper  # noqa: E402
from sb3_genrl.data import write_dataset  # noqa: E402
from sb3_genrl.genrl.demonstrations import DemonstrationCallback  # noqa: E402
from sb3_genrl.vec_env import BatchedLatentVecEnv  # noqa: E402

REFERENCE = pathlib.Path(__file__).parent / "data" / "reference_parameters.npz"
SMALL = {"net_arch": {"pi": [16, 16], "vf": [16, 16]}}  # small networks: a small file


class EncodingLinearGenerator(LinearGenerator):
    """The linear generator with its exact inverse as the encoder: ``alpha = R^-1 (sum_t tau_t - c)``."""

    def encode(self, trajectories):
        alpha = np.linalg.solve(R, (np.asarray(trajectories, np.float64).sum(axis=1) - C).T).T
        return alpha.astype(np.float32), np.zeros_like(alpha, dtype=np.float32)


def _demonstrations(folder: pathlib.Path, n: int = 24, horizon: int = 5) -> pathlib.Path:
    """A dataset of ``n`` demonstrations, each the linear generator's trajectory of a latent action, from its context."""
    rng = np.random.default_rng(7)
    contexts = rng.uniform(-0.8, 0.8, (n, 2)).astype(np.float32)
    latents = (np.sin(3 * contexts) + 0.1 * rng.normal(size=(n, 2))).astype(np.float32)
    arrays = {
        "observations": np.repeat(contexts[:, None, :], horizon + 1, axis=1),
        "actions": LinearGenerator(horizon).decode(latents),
        "rewards": np.zeros((n, horizon)),
        "terminations": np.ones((n, horizon), bool),
        "truncations": np.zeros((n, horizon), bool),
        "reached": contexts.astype(np.float64),
        "sampled_goals": contexts.astype(np.float64),
    }
    return write_dataset(
        folder,
        arrays,
        dataset_id="genrl/fast-reach-v0",
        genrl={"task": "fast-reach", "horizon": horizon},
        observation_space=spaces.Box(-np.inf, np.inf, (2,), np.float32),
        action_space=spaces.Box(-1.0, 1.0, (2,), np.float32),
    )


def _parameters(model: GenRL, name: str) -> dict[str, np.ndarray]:
    """The model's saved tensors: the policy's, the policy average's and the hindsight regression's Adam moments."""
    tensors = {f"policy.{key}": value for key, value in model.policy.state_dict().items()}
    if model.policy_average is not None:
        tensors |= {f"average.{key}": value for key, value in model.policy_average.state_dict().items()}
    for index, state in model.hindsight.optimizer.state_dict()["state"].items():
        tensors |= {f"hindsight_adam.{index}.{key}": value for key, value in state.items()}
    return {f"{name}/{key}": value.detach().cpu().numpy() for key, value in tensors.items()}


def hindsight_run() -> dict[str, np.ndarray]:
    envs = BatchedLatentVecEnv([lambda: LatentActionWrapper(HindsightReachEnv(), LinearGenerator())] * 3, n_threads=1)
    model = GenRL(
        envs,
        seed=5,
        n_steps=8,
        batch_size=8,
        value_history=2,
        policy_averaging=0.9,
        device="cpu",
        policy_kwargs=SMALL,
        hindsight_kwargs={"history": 3, "regression_steps": 8, "regression_batch_size": 16, "regression_weighted": True},
    )
    return _parameters(model.learn(96), "hindsight")


def refits_demonstrations_run() -> dict[str, np.ndarray]:
    envs = DummyVecEnv([lambda: LatentActionWrapper(SuccessReachEnv(), EncodingLinearGenerator())] * 2)
    model = GenRL(
        envs,
        seed=6,
        n_steps=8,
        batch_size=8,
        device="cpu",
        policy_kwargs=SMALL,
        hindsight_kwargs={"history": 2, "regression_steps": 4, "refit_every": 32, "refit_start": 16, "refit_steps": 20},
    )
    with tempfile.TemporaryDirectory() as folder:
        callback = DemonstrationCallback(_demonstrations(pathlib.Path(folder) / "demos"), fit_steps=20, batch_size=8)
        model.learn(80, callback=callback)
    return _parameters(model, "refits_demonstrations")


def machine() -> str:
    """What sets a run's last bits: the CPU (its model and instruction-set flags), torch's version and the kernels it
    dispatches to."""
    cpuinfo = pathlib.Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.exists() else []
    model = next((line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")), platform.processor())
    flags = next((line.split(":", 1)[1].split() for line in lines if line.startswith("flags")), [])
    digest = hashlib.sha256(" ".join(sorted(set(flags))).encode()).hexdigest()[:12]
    return f"{model} (flags {digest}), torch {th.__version__}, {th.backends.cpu.get_cpu_capability()}"


def reference_parameters() -> dict[str, np.ndarray]:
    """The parameters of both runs, by ``run/tensor`` name."""
    return hindsight_run() | refits_demonstrations_run()


if __name__ == "__main__":
    th.set_num_threads(1)
    REFERENCE.parent.mkdir(exist_ok=True)
    np.savez(REFERENCE, machine=np.array(machine()), **reference_parameters())
    print(f"wrote {REFERENCE}")
