"""Shared test set-up and helpers: offscreen rendering, one torch thread (the models are small; CI has 2 cores), the
toy reaching tasks with a known optimum (a linear generator and a point mass, used by the wrapper and GenRL tests),
the command line run as a user runs it, and an independent measure of a trained policy's distance to new goals."""

import atexit
import os
import shutil
import tempfile

os.environ.setdefault("MUJOCO_GL", "egl")
# SB3's logger makes an empty folder in the temporary directory for every learn() given no log folder (its default,
# `configure(None, ...)`): a few hundred per run of the suite. The tests' learns share one, removed at exit.
if "SB3_LOGDIR" not in os.environ:
    os.environ["SB3_LOGDIR"] = tempfile.mkdtemp(prefix="sb3-genrl-tests-")
    atexit.register(shutil.rmtree, os.environ["SB3_LOGDIR"], True)

from collections.abc import Callable  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from gymnasium import spaces  # noqa: E402

from sb3_genrl import utils  # noqa: E402
from sb3_genrl.generative import TrajectoryGenerator  # noqa: E402

# Seconds a test waits on another process before it gives up: a bound against a hang only, far beyond any run on a
# loaded machine. No test passes or fails by how long something took; each waits for a signal (an exit, a line, a file).
HANG_S = 1800


@pytest.fixture(autouse=True)
def one_torch_thread():
    with utils.one_torch_thread():
        yield


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


# u_t = w_t * R alpha + c / T with sum_t w_t = 1: the trajectory's displacement is R alpha + c.
R = np.array([[0.8, 0.3], [-0.2, 0.9]])
C = np.array([0.1, -0.1])


def optimal_latent(goal: np.ndarray) -> np.ndarray:
    """The latent action whose trajectory ends exactly on ``goal`` (reward 0, the maximum)."""
    return np.linalg.solve(R, np.asarray(goal) - C)


class LinearGenerator(TrajectoryGenerator):
    """A linear "generator" of 2-D velocity trajectories: tau_t = w_t R alpha + c / T."""

    def __init__(self, horizon: int = 5, prior: str = "normal") -> None:
        super().__init__(horizon=horizon, action_dim=2, latent_dim=2, prior=prior)  # type: ignore[arg-type]
        self.weights = np.linspace(1.0, 2.0, horizon) / np.linspace(1.0, 2.0, horizon).sum()

    def decode(self, alpha: np.ndarray) -> np.ndarray:
        alpha = self.check_latent(alpha).astype(np.float64)
        displacement = alpha @ R.T  # (n, 2)
        return (self.weights[None, :, None] * displacement[:, None, :] + C / self.horizon).astype(np.float32)

    def save(self, path: str) -> None:
        with open(path, "wb") as file:  # exactly at ``path`` (np.savez would append ".npz" to a name)
            np.savez(file, horizon=self.horizon, prior=self.prior)


def load_linear_generator(path: str, device: object = "cpu") -> LinearGenerator:  # a numpy model: no device
    with np.load(path) as data:
        return LinearGenerator(horizon=int(data["horizon"]), prior=str(data["prior"]))


class ReachEnv(gym.Env):
    """A point mass moved by per-step velocities in [-1, 1]^2; terminal reward -||position - goal||^2.

    Observation: goal and position. Episodes last ``episode_length`` steps; every earlier step costs ``step_cost``.
    """

    metadata = {"render_modes": []}

    def __init__(self, episode_length: int = 5, step_cost: float = 0.0) -> None:
        self.episode_length = episode_length
        self.step_cost = step_cost
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(4,), dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        goal = (options or {}).get("goal")
        self.goal = self.np_random.uniform(-0.8, 0.8, size=2) if goal is None else np.asarray(goal, dtype=np.float64)
        self.position = np.zeros(2)
        self.t = 0
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self.goal, self.position]).astype(np.float32)

    def step(self, action):
        self.position = self.position + np.clip(action, -1.0, 1.0)
        self.t += 1
        terminated = self.t >= self.episode_length
        reward = -float(np.sum((self.position - self.goal) ** 2)) if terminated else -self.step_cost
        return self._obs(), reward, terminated, False, {"reached": self.position.copy()}


class ContextReachEnv(ReachEnv):
    """ReachEnv with the GenRL task context interface (``context_space``, ``get_context``)."""

    context_space = spaces.Box(-0.8, 0.8, shape=(2,), dtype=np.float32)

    def get_context(self) -> np.ndarray:
        return self.goal.astype(np.float32)


class FastReachEnv(ContextReachEnv):
    """ContextReachEnv with the fast open-loop path ``play_trajectories``."""

    def play_trajectories(self, trajectories, goals, *, n_threads=1):
        reached = np.clip(trajectories, -1.0, 1.0).sum(axis=1)
        rewards = -np.sum((reached - goals) ** 2, axis=1)
        return rewards, [{"reward": float(r), "reached": p} for r, p in zip(rewards, reached, strict=True)]


@pytest.fixture
def quickstart_settings(monkeypatch: pytest.MonkeyPatch) -> Callable[..., dict]:
    """Call ``quickstart(out, **kwargs)`` up to its stages and return the settings they would be made with (no stage
    runs)."""
    from sb3_genrl.study import quickstart as module

    def settings(out: os.PathLike, **kwargs: object) -> dict:
        made: dict = {}

        def stages(out, settings, *args):
            made.update(settings)
            raise KeyboardInterrupt  # stop before any work

        monkeypatch.setattr(module, "_run_stages", stages)
        with pytest.raises(KeyboardInterrupt):
            module.quickstart(out, progress_bar=False, **kwargs)
        return made

    return settings
