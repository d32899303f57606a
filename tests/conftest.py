"""Shared test set-up and helpers: offscreen rendering, one torch thread (the models are small; CI has 2 cores), the
command line run as a user runs it, and an independent measure of a trained policy's distance to new goals."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from collections.abc import Callable  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402


@pytest.fixture(autouse=True)
def one_torch_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def cli(capsys: pytest.CaptureFixture[str]) -> Callable[..., tuple[int, str, str]]:
    """Run ``genrl ARGS...`` in-process: returns the exit status, stdout and stderr (argparse's exits included)."""
    from sb3_genrl.cli import main

    def run(*argv: object) -> tuple[int, str, str]:
        try:
            code = main([str(arg) for arg in argv])
        except SystemExit as exit_:
            code = exit_.code
        captured = capsys.readouterr()
        return code, captured.out, captured.err

    return run


@pytest.fixture(scope="session")
def hockey_generator(tmp_path_factory: pytest.TempPathFactory) -> str:
    """An untrained 2-D beta-VAE for the hockey task (69 steps, 7 joints), saved to a file."""
    from sb3_genrl.generative import make_generator

    path = tmp_path_factory.mktemp("generator") / "vae.pt"
    make_generator("VAE1", horizon=69, action_dim=7, device="cpu").save(str(path))
    return str(path)


def policy_distances(policy_zip: os.PathLike | str, env_id: str, goals: int, seed: int) -> np.ndarray:
    """The final distances (m) of a saved GenRL policy's deterministic trajectories to ``goals`` goals drawn as the
    package draws them (``env.sample_goal`` with ``np.random.default_rng(seed)``), played through the task itself."""
    from sb3_genrl import GenRL

    model = GenRL.load(policy_zip, device="cpu")
    env = gym.make(env_id).unwrapped
    rng = np.random.default_rng(seed)
    goal_array = np.array([env.sample_goal(rng) for _ in range(goals)], dtype=np.float32)
    trajectories = model.generator.decode(model.predict(goal_array, deterministic=True)[0])
    _, infos = env.play_trajectories(trajectories, goal_array)
    return np.array([info["distance"] for info in infos])
