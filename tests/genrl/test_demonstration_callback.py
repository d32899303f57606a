"""Learning from demonstrations (sb3_genrl/genrl/demonstrations.py): the fit of the policy's mean against least
squares, the demonstrations kept in every E-step and regression, resumed runs, and the errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch as th
from conftest import C, LinearGenerator, R
from genrl_test_helpers import HindsightReachEnv, SuccessOnlyReachEnv
from gymnasium import spaces
from stable_baselines3.common.logger import Logger
from test_checkpoint import _Killed, _parameters, hindsight_task  # noqa: F401 (the fixture)
from test_train_policy import fast_reach_task  # noqa: F401 (the fixture)

from sb3_genrl import GenRL
from sb3_genrl.data import write_dataset
from sb3_genrl.genrl import demonstrations as demonstrations_module
from sb3_genrl.genrl.demonstrations import DEMONSTRATION_CALLBACK, DemonstrationCallback, build_callbacks
from sb3_genrl.run import train_policy

N, HORIZON = 48, 5


class EncodingLinearGenerator(LinearGenerator):
    """The linear generator with its exact inverse as the encoder: ``alpha = R^-1 (sum_t tau_t - c)``."""

    def encode(self, trajectories):
        alpha = np.linalg.solve(R, (np.asarray(trajectories, np.float64).sum(axis=1) - C).T).T
        return alpha.astype(np.float32), np.zeros_like(alpha, dtype=np.float32)


def _dataset(path, contexts: np.ndarray, latents: np.ndarray, horizon: int = HORIZON, *, reached=None, observations=None):
    """A dataset whose episode i plays the linear generator's trajectory of ``latents[i]`` from context
    ``contexts[i]`` (its first observation, unless ``observations`` (N, D) are given; ``reached`` (default: the
    contexts) are the points its episodes reached)."""
    n = len(contexts)
    actions = LinearGenerator(horizon).decode(latents)
    first = contexts if observations is None else observations
    observations = np.repeat(first[:, None, :], horizon + 1, axis=1).astype(np.float32)
    arrays = {
        "observations": observations,
        "actions": actions,
        "rewards": np.zeros((n, horizon)),
        "terminations": np.ones((n, horizon), bool),
        "truncations": np.zeros((n, horizon), bool),
        "reached": (contexts if reached is None else reached).astype(np.float64),
        "sampled_goals": contexts.astype(np.float64),
    }
    dim = first.shape[1]
    return write_dataset(
        path,
        arrays,
        dataset_id="genrl/fast-reach-v0",
        genrl={"task": "fast-reach", "horizon": horizon},
        observation_space=spaces.Box(-np.inf, np.inf, (dim,), np.float32),
        action_space=spaces.Box(-1.0, 1.0, (2,), np.float32),
    )


@pytest.fixture
def demos(tmp_path):
    """Demonstrations whose latent actions are a non-linear function of the context plus noise."""
    rng = np.random.default_rng(0)
    contexts = rng.uniform(-0.8, 0.8, (N, 2)).astype(np.float32)
    latents = np.sin(3 * contexts) + contexts @ np.array([[0.5, -1.0], [1.0, 0.2]]) + 0.1 * rng.normal(size=(N, 2))
    return _dataset(tmp_path / "demos", contexts, latents.astype(np.float32)), contexts, latents


def _short_run(out_dir, **kwargs):
    """``train_policy`` of 32 fast-reach episodes, 16 an iteration, into ``out_dir``."""
    return train_policy("fast-reach", EncodingLinearGenerator(), episodes=32, batch_episodes=16, out_dir=out_dir, **kwargs)


def _model(**kwargs):
    return GenRL(HindsightReachEnv(), EncodingLinearGenerator(), seed=1, n_steps=16, batch_size=16, **kwargs)


def test_the_fit_lowers_the_loss_and_reaches_the_least_squares_mean(demos):
    dataset, contexts, latents = demos
    # no hidden layer: the mean is affine in the context (BoxScaler is affine), so the best fit is least squares
    model = _model(policy_kwargs={"net_arch": {"pi": [], "vf": [8]}}, hindsight_kwargs={})
    callback = DemonstrationCallback(dataset, fit_steps=3000, learning_rate=0.005, batch_size=N, keep=False)
    model.set_logger(Logger(folder=None, output_formats=[]))
    callback.init_callback(model)
    callback.on_training_start({}, {})  # as learn() starts a fresh run
    design = np.hstack([contexts.astype(np.float64), np.ones((N, 1))])
    solution, *_ = np.linalg.lstsq(design, latents.astype(np.float64), rcond=None)
    least_squares = design @ solution
    mean = model.predict(contexts, deterministic=True)[0]
    np.testing.assert_allclose(mean, least_squares, atol=0.03)  # (the minibatches drawn with replacement)
    assert callback.fit["demonstrations"] == N and callback.fit["steps"] == 3000
    best = np.mean((least_squares - latents) ** 2)
    assert callback.fit["last_loss"] < 0.2 * callback.fit["first_loss"] and callback.fit["last_loss"] == pytest.approx(
        best, rel=0.1
    )
    assert model.logger.name_to_value["demonstrations/last_loss"] == callback.fit["last_loss"]


def test_a_task_whose_context_is_the_goal_takes_the_points_the_demonstrations_reached(demos, tmp_path):
    """As hockey's: the first observation is the robot's state, the context the goal, which each demonstration's
    reached point is; a demonstration that records none is left out, and a dataset where none does is refused."""
    _, contexts, latents = demos
    states = np.random.default_rng(1).normal(size=(N, 5)).astype(np.float32)  # not contexts: 5-D
    reached = contexts.astype(np.float64)
    reached[[3, 7]] = np.nan
    dataset = _dataset(tmp_path / "goal", contexts, latents.astype(np.float32), reached=reached, observations=states)
    got_contexts, got_latents = DemonstrationCallback(dataset).pulls(EncodingLinearGenerator(), spaces.Box(-1, 1, (2,)), 3.0)
    rows = np.setdiff1d(np.arange(N), [3, 7])
    np.testing.assert_array_equal(got_contexts.numpy(), contexts[rows])
    np.testing.assert_allclose(got_latents.numpy(), np.clip(latents[rows], -3, 3), atol=1e-5)
    # where the first observation has the context's shape it stays the context (the Fetch tasks, Meta-World)
    same = _dataset(tmp_path / "state", contexts, latents.astype(np.float32), reached=reached[:, ::-1].copy())
    np.testing.assert_array_equal(
        DemonstrationCallback(same).pulls(EncodingLinearGenerator(), spaces.Box(-1, 1, (2,)), 3.0)[0].numpy(), contexts
    )
    none = _dataset(
        tmp_path / "none", contexts, latents.astype(np.float32), reached=np.full((N, 2), np.nan), observations=states
    )
    with pytest.raises(ValueError, match="none records the point it reached"):
        DemonstrationCallback(none).pulls(EncodingLinearGenerator(), spaces.Box(-1, 1, (2,)), 3.0)


class _BatchRecorder(GenRL):
    """GenRL that keeps the first E-step batch of every iteration."""

    def _e_step(self, q, batch):
        self.batches = getattr(self, "batches", [])
        if len(self.batches) == self._n_updates:
            self.batches.append([t.clone() for t in batch])
        return super()._e_step(q, batch)


def _record_fits(monkeypatch, module, name):
    """Patch ``module.name`` (a fit of the mean: ``regress_mean`` or ``fit_mean``) to record the (contexts, latent
    actions) of each call, then fit as before; the list of records."""
    calls, fit = [], getattr(module, name)

    def recorded(*args, **kwargs):
        x, y = (arg for arg in args if isinstance(arg, th.Tensor))
        calls.append((x.clone(), y.clone()))
        return fit(*args, **kwargs)

    monkeypatch.setattr(module, name, recorded)
    return calls


def test_kept_demonstrations_join_every_e_step_and_every_regression(demos, monkeypatch):
    from sb3_genrl.genrl import hindsight

    dataset, contexts, latents = demos
    regressed = _record_fits(monkeypatch, hindsight, "regress_mean")
    model = _BatchRecorder(
        HindsightReachEnv(),
        EncodingLinearGenerator(),
        seed=1,
        n_steps=16,
        batch_size=16,
        hindsight_kwargs={"history": 1, "regression_steps": 2},
    )
    model.learn(48, callback=DemonstrationCallback(dataset, fit_steps=0))
    assert len(model.batches) == len(regressed) == 3
    clipped = np.clip(latents, -3, 3).astype(np.float32)  # the latents as the dataset's actions encode them
    for (observations, actions, _, advantages), (x, y) in zip(model.batches, regressed, strict=True):
        # after the 16 played and this batch's relabelled pulls (history 1): the N demonstrations, every iteration
        np.testing.assert_allclose(observations[-N:].numpy(), contexts, atol=1e-6)
        np.testing.assert_allclose(actions[-N:].numpy(), clipped, atol=1e-5)
        assert len(observations) == 16 + (len(x) - N) + N and np.all(np.isfinite(advantages.numpy()))
        np.testing.assert_allclose(x[-N:].numpy(), contexts, atol=1e-6)
        np.testing.assert_allclose(y[-N:].numpy(), clipped, atol=1e-5)


def test_refit_demonstrations_join_every_refit_after_the_solving_pulls(demos, fast_reach_task, tmp_path, monkeypatch):  # noqa: F811
    from sb3_genrl.genrl import refits as refits_module

    dataset, contexts, latents = demos
    fitted = _record_fits(monkeypatch, refits_module, "fit_mean")
    model = GenRL(
        SuccessOnlyReachEnv(),  # no relabelling: history 0
        EncodingLinearGenerator(),
        seed=1,
        n_steps=16,
        batch_size=16,
        hindsight_kwargs={"history": 0, "refit_every": 16, "refit_steps": 5},
    )
    model.learn(32, callback=DemonstrationCallback(dataset, fit_steps=0, keep=False, refit=True))
    assert len(fitted) == 2 and model.kept_pulls.pulls is None
    clipped = np.clip(latents, -3, 3).astype(np.float32)
    for batches, (x, y) in enumerate(fitted, start=1):  # the solving pulls of the batches so far, then the demonstrations
        solved_x, solved_y = (th.cat(part) for part in zip(*model.refits.solved[:batches], strict=True))
        assert len(x) == len(solved_x) + N
        th.testing.assert_close(x[: len(solved_x)], solved_x, rtol=0, atol=0)
        th.testing.assert_close(y[: len(solved_x)], solved_y, rtol=0, atol=0)
        np.testing.assert_allclose(x[-N:].numpy(), contexts, atol=1e-6)
        np.testing.assert_allclose(y[-N:].numpy(), clipped, atol=1e-5)
    assert model.logger.name_to_value["train/refit_pairs"] == len(fitted[-1][0])
    # refit=True without the refits: refused before any work
    with pytest.raises(ValueError, match=r"refit=True\) adds the demonstrations to the refits.*refit_every"):
        _short_run(
            tmp_path / "run",
            hindsight_kwargs={},
            callback=[{DEMONSTRATION_CALLBACK: {"fit_steps": 0, "keep": False, "refit": True}}],
            demonstrations=dataset,
        )
    assert not (tmp_path / "run").exists()
    with pytest.raises(ValueError, match="DemonstrationCallback: refit must be True or False, got 'yes'"):
        DemonstrationCallback(dataset, refit="yes")


def test_a_resumed_run_keeps_the_demonstrations_and_is_not_fitted_again(
    hindsight_task,  # noqa: F811
    demos,
    tmp_path,
    monkeypatch,
):
    dataset, _, _ = demos
    fits = []
    fit = demonstrations_module.fit_mean_to_demonstrations
    monkeypatch.setattr(
        demonstrations_module, "fit_mean_to_demonstrations", lambda *args, **kwargs: fits.append(1) or fit(*args, **kwargs)
    )
    settings = {
        "episodes": 128,
        "seed": 3,
        "batch_episodes": 32,
        "policy_averaging": 0.9,
        "checkpoint_every": 64,
        "hindsight_kwargs": {"history": 2, "regression_steps": 4},
        "demonstrations": dataset,
        "callback": [{DEMONSTRATION_CALLBACK: {"fit_steps": 20}}],
    }
    whole = train_policy("fast-reach", EncodingLinearGenerator(), out_dir=tmp_path / "whole", **settings)
    assert len(fits) == 1
    learn = GenRL.train
    monkeypatch.setattr(
        GenRL, "train", lambda model: learn(model) if model._n_updates < 3 else (_ for _ in ()).throw(_Killed())
    )  # killed in the fourth update: the checkpoint is at 64 episodes
    with pytest.raises(_Killed):
        train_policy("fast-reach", EncodingLinearGenerator(), out_dir=tmp_path / "stopped", **settings)
    (memories,) = (th.load(path, weights_only=True) for path in (tmp_path / "stopped" / "checkpoint").glob("memories*"))
    assert len(memories["hindsight_kept_pulls"][0]) == N  # the demonstrations, in the checkpoint
    monkeypatch.setattr(GenRL, "train", learn)
    resumed = train_policy("fast-reach", EncodingLinearGenerator(), out_dir=tmp_path / "stopped", **settings)
    assert len(fits) == 2 and resumed["resumed_at_episodes"] == [64]  # the stopped run's fit only, none on resume
    expected, got = (_parameters(tmp_path / name / "genrl_policy.zip") for name in ("whole", "stopped"))
    for key in expected:
        np.testing.assert_array_equal(got[key], expected[key], err_msg=key)
    assert resumed["final_mean_reward"] == whole["final_mean_reward"]
    record = json.loads((tmp_path / "whole" / "run_record.json").read_text())
    from sb3_genrl.data.fingerprints import dataset_fingerprint

    assert dataset_fingerprint(dataset) in json.dumps(record)  # the demonstrations are part of the run's identity


def test_missing_or_unfitting_demonstrations_are_refused_before_any_work(fast_reach_task, demos, tmp_path):  # noqa: F811
    dataset, contexts, latents = demos
    callback = [{DEMONSTRATION_CALLBACK: {"fit_steps": 10}}]
    with pytest.raises(
        ValueError,
        match=r"learn from demonstrations .* need their dataset: give it .*--data DIR.*"
        r"`genrl demos --task fast-reach --episodes 4000 --out DIR`",
    ):
        _short_run(tmp_path / "run", hindsight_kwargs={}, callback=callback)
    assert not (tmp_path / "run").exists()
    with pytest.raises(ValueError, match="do not learn from demonstrations"):
        build_callbacks(None, demonstrations=dataset)
    with pytest.raises(ValueError, match="no demonstration dataset at"):
        DemonstrationCallback(tmp_path / "none")
    with pytest.raises(ValueError, match="needs GenRL's hindsight_kwargs"):
        _short_run(tmp_path / "run", callback=callback, demonstrations=dataset)
    with pytest.raises(ValueError, match=r"trajectories of shape \(5, 2\).*the generator makes \(4, 2\)"):
        DemonstrationCallback(dataset).pulls(EncodingLinearGenerator(4), spaces.Box(-1, 1, (2,)), 3.0)
    with pytest.raises(ValueError, match="needs a generator with an encoder"):
        DemonstrationCallback(dataset).pulls(LinearGenerator(), spaces.Box(-1, 1, (2,)), 3.0)
    wide = _dataset(tmp_path / "wide", np.hstack([contexts, contexts[:, :1]]), latents.astype(np.float32))
    with pytest.raises(ValueError, match=r"context is its first observation, of shape \(3,\), or else the point it reached"):
        _short_run(tmp_path / "run", hindsight_kwargs={}, callback=callback, demonstrations=wide)
    assert not (tmp_path / "run").exists()
    with pytest.raises(ValueError, match="'fit_step' not among DemonstrationCallback's arguments"):
        build_callbacks([{DEMONSTRATION_CALLBACK: {"fit_step": 10}}], demonstrations=dataset)
    with pytest.raises(ValueError, match="fit_steps must be an integer >= 0"):
        build_callbacks([{DEMONSTRATION_CALLBACK: {"fit_steps": -1}}], demonstrations=dataset)


def test_the_fetch_entries_name_the_callback_and_a_bad_one_is_refused():
    from sb3_genrl.genrl.demonstrations import callback_entries, uses_demonstrations
    from sb3_genrl.hyperparams import load_genrl_settings

    for env_id in ("FetchReach-v4", "FetchPush-v4", "FetchPickAndPlace-v4", "FetchSlide-v4"):
        callback = load_genrl_settings(env_id)[2]["callback"]
        assert callback == [{DEMONSTRATION_CALLBACK: {"fit_steps": 4000, "keep": True, "scale_contexts": True}}]
        assert uses_demonstrations(callback)
    assert "callback" not in load_genrl_settings("GenRL/Hockey-v0")[2]
    assert callback_entries(DEMONSTRATION_CALLBACK) == [(DEMONSTRATION_CALLBACK, {})]  # rl-zoo3's other forms
    with pytest.raises(ValueError, match="expected a callback class path or"):
        callback_entries([{"a": {}, "b": {}}])
    with pytest.raises(ValueError, match="would not use the demonstrations"):
        callback_entries([{DEMONSTRATION_CALLBACK: {"fit_steps": 0, "keep": False}}])
    with pytest.raises(ValueError, match="scale_contexts must be True or False, got 'yes'"):
        callback_entries([{DEMONSTRATION_CALLBACK: {"scale_contexts": "yes"}}])
