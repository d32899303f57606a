"""Hindsight relabelling (sb3_genrl/genrl/hindsight.py, hindsight_buffer.py, refits.py): the relabelled batch, the
history, the regression of the mean, the rollout buffer that stores each pull's relabelling, the refits, on their own and
inside GenRL."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from conftest import (
    FastReachEnv,
    LinearGenerator,
    optimal_latent,
)
from genrl_test_helpers import GOALS, EStepBatchRecorder, HindsightReachEnv, SuccessOnlyReachEnv, SuccessReachEnv
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv

import sb3_genrl.genrl.genrl as genrl_module
from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.genrl.hindsight import HindsightRelabelling
from sb3_genrl.genrl.hindsight_buffer import HindsightRolloutBuffer
from sb3_genrl.genrl.kept_pulls import KeptPulls
from sb3_genrl.genrl.refits import Refits
from sb3_genrl.genrl.regression import mean_parameters, regress_mean


def test_hindsight_relabels_each_pull_with_the_point_its_own_action_reached():
    # Two envs, so a pull paired with another pull's action would show. The linear generator's reached point is
    # computed here from each relabelled action on its own (decode, clip the steps, sum), independently of the infos.
    envs = DummyVecEnv([lambda: LatentActionWrapper(HindsightReachEnv(), LinearGenerator())] * 2)
    model = EStepBatchRecorder("MlpPolicy", envs, seed=3, n_steps=16, hindsight_kwargs={})
    model.learn(32)
    (observations, actions, log_prob_pi, advantages), values, log_prob, buffer_advantages = model.recorded
    n_played = 32
    played_actions = np.clip(actions[:n_played].numpy(), -3, 3)
    reached = np.clip(LinearGenerator().decode(played_actions), -1, 1).sum(axis=1)
    inside = np.all(np.abs(reached) <= 0.8, axis=1)
    assert 0 < inside.sum() < n_played  # some pulls land outside the context box, and are left out
    assert len(observations) == n_played + inside.sum()
    relabelled = slice(n_played, None)
    relabelled_actions = np.clip(actions[relabelled].numpy(), -3, 3)
    expected_contexts = np.clip(LinearGenerator().decode(relabelled_actions), -1, 1).sum(axis=1)
    np.testing.assert_allclose(observations[relabelled].numpy(), expected_contexts, atol=1e-5)
    np.testing.assert_allclose(
        np.sort(actions[relabelled].numpy(), axis=0), np.sort(actions[:n_played].numpy()[inside], axis=0)
    )
    np.testing.assert_allclose(log_prob_pi[relabelled].numpy(), log_prob[relabelled].numpy(), rtol=1e-5)
    raw = th.as_tensor(buffer_advantages.flatten())
    expected = (0.0 - values[relabelled] - raw.mean()) / (raw.std() + 1e-8)
    np.testing.assert_allclose(advantages[relabelled].numpy(), expected.numpy(), rtol=1e-4, atol=1e-5)
    assert model.logger.name_to_value["train/hindsight_pulls"] == pytest.approx(inside.sum() / n_played)


class _EveryBatchRecorder(GenRL):
    """GenRL that keeps the first E-step batch of every iteration, with the policy's log-probabilities then and the
    actions as played."""

    def _e_step(self, q, batch):
        self.recorded = getattr(self, "recorded", [])
        if len(self.recorded) == self._n_updates:
            with th.no_grad():
                log_prob = self.policy.get_distribution(batch[0]).log_prob(batch[1])
            played = self.rollout_buffer.actions.reshape(-1, self.action_space.shape[0]).copy()
            self.recorded.append(([t.clone() for t in batch], log_prob, played))
        return super()._e_step(q, batch)


def test_hindsight_history_keeps_the_relabelled_pulls_of_the_last_batches():
    model = _EveryBatchRecorder(
        LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=1, n_steps=16, hindsight_kwargs={"history": 2}
    )
    model.learn(64)  # four iterations
    inside_actions = []
    for iteration, ((observations, actions, log_prob_pi, _), log_prob, played) in enumerate(model.recorded):
        reached = np.clip(LinearGenerator().decode(np.clip(played, -3, 3)), -1, 1).sum(axis=1)
        inside_actions.append(played[np.all(np.abs(reached) <= 0.8, axis=1)])
        kept = np.concatenate(inside_actions[max(0, iteration - 1) :])  # this batch's and the one before
        relabelled = slice(len(played), None)
        assert len(observations) == len(played) + len(kept)
        np.testing.assert_allclose(np.sort(actions[relabelled].numpy(), axis=0), np.sort(kept, axis=0))
        expected_contexts = np.clip(LinearGenerator().decode(np.clip(actions[relabelled].numpy(), -3, 3)), -1, 1)
        np.testing.assert_allclose(observations[relabelled].numpy(), expected_contexts.sum(axis=1), atol=1e-5)
        # the earlier batch's pulls are weighed with the current policy, not the one that played them
        np.testing.assert_allclose(log_prob_pi[relabelled].numpy(), log_prob[relabelled].numpy(), rtol=1e-5)
    assert len(model.recorded) == 4 and all(len(actions) > 0 for actions in inside_actions)


class _NothingReachedEnv(FastReachEnv):
    def hindsight(self, info):
        return None


def test_hindsight_with_no_pull_to_relabel_leaves_the_batch_as_played():
    model = EStepBatchRecorder(
        "MlpPolicy", LatentActionWrapper(_NothingReachedEnv(), LinearGenerator()), seed=0, n_steps=16, hindsight_kwargs={}
    )
    model.learn(16)
    observations = model.recorded[0][0]
    assert len(observations) == 16 and model.logger.name_to_value["train/hindsight_pulls"] == 0


def test_hindsight_reaches_new_goals_sooner_on_the_toy():
    distances = {}
    for hindsight_kwargs in (None, {}):
        model = GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, hindsight_kwargs=hindsight_kwargs)
        model.learn(640)
        after = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
        distances[hindsight_kwargs is not None] = np.abs(after - np.array([optimal_latent(goal) for goal in GOALS])).max()
    assert distances[True] < 0.6 * distances[False]  # 0.013 against 0.031 (seeds 1 and 2: 0.52 and 0.41 times)


def test_hindsight_regression_reaches_new_goals_sooner_on_the_toy():
    distances = {}
    for steps in (0, 256):
        model = GenRL(
            LatentActionWrapper(HindsightReachEnv(), LinearGenerator()),
            seed=0,
            n_steps=16,
            hindsight_kwargs={"history": 8, "regression_steps": steps},
        )
        model.learn(320)
        after = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
        distances[steps] = np.abs(after - np.array([optimal_latent(goal) for goal in GOALS])).max()
    assert distances[256] < 0.5 * distances[0]  # 0.007 against 0.037 (seeds 1 and 2: 0.12 and 0.37 times)
    assert model.logger.name_to_value["train/hindsight_regression_loss"] > 0


def test_hindsight_regression_keeps_its_optimizer_across_save_and_load(tmp_path):
    model = GenRL(
        LatentActionWrapper(HindsightReachEnv(), LinearGenerator()),
        seed=0,
        n_steps=16,
        hindsight_kwargs={"regression_steps": 4, "regression_lr": 3e-4, "regression_batch_size": 32},
    )
    model.learn(32)
    assert "hindsight.optimizer" in model._get_torch_save_params()[0]
    state = model.hindsight.optimizer.state_dict()
    assert state["param_groups"][0]["lr"] == 3e-4 and all(v["step"] == 8 for v in state["state"].values())
    model.save(tmp_path / "model")
    loaded = GenRL.load(tmp_path / "model.zip", env=HindsightReachEnv(), generator=LinearGenerator())
    assert (loaded.hindsight.regression_steps, loaded.hindsight.regression_batch_size) == (4, 32)
    assert loaded.hindsight_kwargs == {"regression_steps": 4, "regression_lr": 3e-4, "regression_batch_size": 32}
    for before, after in zip(state["state"].values(), loaded.hindsight.optimizer.state_dict()["state"].values(), strict=True):
        th.testing.assert_close(after["exp_avg"], before["exp_avg"])
    assert len(loaded.hindsight.memory) == 0  # the kept pulls are not saved: a loaded model keeps them anew
    assert GenRL(FastReachEnv(), LinearGenerator(), hindsight_kwargs={}).hindsight.optimizer is None  # no regression
    assert GenRL(FastReachEnv(), LinearGenerator()).hindsight is None  # no relabelling


def test_hindsight_switched_on_at_load_relabels_from_then_on(tmp_path):
    GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, n_steps=16).learn(16).save(tmp_path / "m")
    loaded = GenRL.load(
        tmp_path / "m.zip", env=HindsightReachEnv(), generator=LinearGenerator(), hindsight_kwargs={"regression_steps": 2}
    )
    loaded.learn(16)
    assert loaded.logger.name_to_value["train/hindsight_pulls"] > 0 and len(loaded.hindsight.memory) == 1
    assert all(value["step"] == 2 for value in loaded.hindsight.optimizer.state_dict()["state"].values())


@pytest.fixture
def trained():
    """A GenRL model after one iteration of 8 pulls: its policy, value function and rollout buffer (after get())."""
    return GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, n_steps=8, device="cpu").learn(8)


def _relabel_infos(contexts, rewards):
    """One step's infos (one env) per context: ``None`` for a pull that reached nothing."""
    return [
        [{"hindsight": None if context is None else (np.asarray(context, np.float32), reward)}]
        for context, reward in zip(contexts, rewards, strict=True)
    ]


def _buffer(trained, **kwargs):
    """An empty hindsight rollout buffer of 8 pulls for the trained model's spaces."""
    return HindsightRolloutBuffer(8, trained.observation_space, trained.action_space, device="cpu", **kwargs)


def _filled(trained, step_infos, **kwargs):
    """A hindsight rollout buffer holding the trained model's 8 pulls as played (one env), each step with its infos."""
    played, buffer = trained.rollout_buffer, _buffer(trained, **kwargs)
    for step, infos in enumerate(step_infos):
        buffer.add_infos(infos)
        observation, action = played.observations[step][None], played.actions[step][None]
        buffer.add(observation, action, np.zeros(1), np.ones(1), th.zeros(1, 1), th.zeros(1))
    return buffer


# contexts of 8 pulls: inside the box, None (nothing reached), outside the box, not finite
CONTEXTS = [[0.1, 0.2], None, [0.9, 0.0], [-0.3, 0.5], [np.nan, 0.0], [0.8, -0.8], [0.0, 0.0], None]
REWARDS = [0.0, 0.0, -1.0, -0.5, 0.0, -0.1, -2.0, 0.0]
INSIDE = [0, 3, 5, 6]


def test_extend_batch_against_an_independent_recomputation(trained):
    hindsight = HindsightRelabelling(trained.policy)
    buffer = _filled(trained, _relabel_infos(CONTEXTS, REWARDS))
    played = (th.randn(8, 2), th.randn(8, 2), th.randn(8), th.randn(8))
    joined, fraction = hindsight.extend_batch(played, buffer.relabelled_pulls(), 0.5, 2.0)
    assert fraction == len(INSIDE) / 8 and all(len(part) == 8 + len(INSIDE) for part in joined)
    for part, original in zip(joined, played, strict=True):
        th.testing.assert_close(part[:8], original, rtol=0, atol=0)  # the pulls as played come first, unchanged
    contexts = th.tensor([CONTEXTS[i] for i in INSIDE], dtype=th.float32)
    actions = th.as_tensor(trained.rollout_buffer.actions[INSIDE].reshape(-1, 2))
    th.testing.assert_close(joined[0][8:], contexts)
    th.testing.assert_close(joined[1][8:], actions)
    with th.no_grad():  # the Gaussian's log density written out, at the relabelled contexts
        distribution = trained.policy.get_distribution(contexts).distribution
        mean, std = distribution.mean, distribution.stddev
        values = trained.policy.predict_values(contexts).flatten()
    log_density = (-0.5 * ((actions - mean) / std) ** 2 - th.log(std) - 0.5 * np.log(2 * np.pi)).sum(1)
    th.testing.assert_close(joined[2][8:], log_density, rtol=1e-5, atol=1e-5)
    expected = (th.tensor([REWARDS[i] for i in INSIDE]) - values - 0.5) / 2.0
    th.testing.assert_close(joined[3][8:], expected)


def test_history_keeps_the_relabelled_pulls_of_the_last_batches_only(trained):
    hindsight = HindsightRelabelling(trained.policy, history=2)
    played = (th.zeros(8, 2), th.zeros(8, 2), th.zeros(8), th.zeros(8))
    kept = []
    for batch in range(3):
        contexts = [[0.1 * batch, 0.0]] * (batch + 1) + [None] * (7 - batch)  # batch + 1 pulls relabelled
        buffer = _filled(trained, _relabel_infos(contexts, [0.0] * 8))
        joined, fraction = hindsight.extend_batch(played, buffer.relabelled_pulls(), 0.0, 1.0)
        kept.append(batch + 1)
        assert len(hindsight.memory) == min(batch + 1, 2) and hindsight.memory.maxlen == 2
        assert len(joined[0]) == 8 + sum(kept[-2:]) and fraction == sum(kept[-2:]) / 8
    np.testing.assert_allclose(joined[0][8:, 0].numpy(), [0.1] * 2 + [0.2] * 3)  # the oldest kept batch first


def test_regression_moves_the_mean_towards_the_kept_pulls(trained):
    policy = trained.policy
    hindsight = HindsightRelabelling(policy, regression_steps=200, regression_lr=1e-2, regression_batch_size=4)
    assert hindsight.regress() == []  # nothing kept yet
    contexts = th.tensor([CONTEXTS[i] for i in INSIDE], dtype=th.float32)
    targets = th.tensor([[1.0, -1.0], [0.5, 0.5], [-1.0, 0.0], [0.0, 1.5]])
    hindsight.memory.append((contexts, targets, th.zeros(4)))
    log_std = policy.log_std.detach().clone()
    with th.no_grad():
        before = (policy.get_distribution(contexts).distribution.mean - targets).abs().max().item()
    losses = hindsight.regress()
    with th.no_grad():
        after = (policy.get_distribution(contexts).distribution.mean - targets).abs().max().item()
    assert len(losses) == 200 and losses[-1] < 0.1 * losses[0]
    assert after < 0.2 * before
    th.testing.assert_close(policy.log_std, log_std, rtol=0, atol=0)  # the spread is left to the E-step
    assert HindsightRelabelling(policy, history=3).regress() == []  # no regression


def test_infos_are_checked_and_reset(trained):
    buffer = _buffer(trained)
    with pytest.raises(ValueError, match=r"info\['hindsight'\]"):
        buffer.add_infos([{"reached": np.zeros(2)}])
    with pytest.raises(ValueError, match="add_infos: 2 infos for a step of 1 envs"):
        buffer.add_infos(_relabel_infos(CONTEXTS[:2], REWARDS[:2])[0] * 2)
    with pytest.raises(RuntimeError, match="HindsightRolloutBuffer.add: no infos for this step"):
        buffer.add(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros(1), np.ones(1), th.zeros(1, 1), th.zeros(1))
    buffer.add_infos(_relabel_infos(CONTEXTS[:1], REWARDS[:1])[0])
    buffer.reset()  # a rollout starts: the infos held before are forgotten
    assert buffer.infos is None and buffer.pos == 0


SOLVED = [True, False, True, True, False, False, True, False]


def _success_infos(solved):
    """One step's infos (one env) per pull: nothing to relabel, and whether it solved its own context."""
    return [[{"hindsight": None, "is_success": flag}] for flag in solved]


def test_refit_fits_the_mean_from_its_initial_weights_to_the_solving_pulls_alone(trained):
    import copy

    policy, played = trained.policy, trained.rollout_buffer
    mean_refits = Refits(policy, every=16, start=8, steps=50, learning_rate=1e-2, batch_size=4)
    initial = [parameter.detach().clone() for parameter in mean_parameters(policy)]
    rows = [i for i, flag in enumerate(SOLVED) if flag]
    contexts = th.as_tensor(played.observations[rows]).float()
    actions = th.as_tensor(np.clip(played.actions[rows], -3, 3)).float()
    for episodes, refits in ((8, True), (16, False), (24, True), (32, False)):  # at 8, then every 16; 8 per batch
        for parameter in mean_parameters(policy):  # the mean moves on between refits
            parameter.data.add_(0.5)
        buffer = _filled(trained, _success_infos(SOLVED), success=True)
        before = [parameter.detach().clone() for parameter in mean_parameters(policy)]
        if refits:  # recomputed here: the initial weights fitted by a new Adam to the solving pulls so far, as played
            expected = copy.deepcopy(policy)
            with th.no_grad():
                for parameter, value in zip(mean_parameters(expected), initial, strict=True):
                    parameter.copy_(value)
            th.manual_seed(episodes)
            losses = regress_mean(
                expected,
                th.optim.Adam(mean_parameters(expected), lr=1e-2),
                th.cat([contexts] * (episodes // 8)),
                th.cat([actions] * (episodes // 8)),
                steps=50,
                batch_size=4,
            )
            th.manual_seed(episodes)
        stats = mean_refits.refit(buffer, episodes)
        assert len(mean_refits.solved) == episodes // 8
        if not refits:
            assert stats == {}
            for parameter, value in zip(mean_parameters(policy), before, strict=True):
                th.testing.assert_close(parameter, value, rtol=0, atol=0)
            continue
        assert stats["refit_pairs"] == episodes // 8 * len(rows)
        assert stats["refit_loss"] == pytest.approx(np.mean(losses[-100:]))
        for parameter, value in zip(mean_parameters(policy), mean_parameters(expected), strict=True):
            th.testing.assert_close(parameter, value, rtol=0, atol=0)
        th.testing.assert_close(policy.log_std, expected.log_std, rtol=0, atol=0)  # the spread is left as it was
    with pytest.raises(ValueError, match=r"info\['is_success'\]"):
        _buffer(trained, success=True).add_infos([{"hindsight": None}])
    no_refits = GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), hindsight_kwargs={})
    assert no_refits.refits is None and no_refits.rollout_buffer_kwargs == {"success": False, "relabel": True}


def test_refit_inside_genrl_logs_its_pairs_and_brings_the_mean_to_the_solving_pulls():
    model = GenRL(
        LatentActionWrapper(SuccessReachEnv(), LinearGenerator()),
        seed=0,
        n_steps=32,
        device="cpu",
        hindsight_kwargs={"refit_every": 64, "refit_steps": 300, "regression_lr": 1e-2},
    )
    model.learn(64)
    pairs = model.logger.name_to_value["train/refit_pairs"]
    contexts, actions = (th.cat(part) for part in zip(*model.refits.solved, strict=True))
    assert pairs == len(actions) > 0 and len(model.refits.solved) == 2
    with th.no_grad():
        error = (model.policy.get_distribution(contexts).distribution.mean - actions).pow(2).mean().item()
    assert error < 0.5 * actions.var(0).mean().item()  # closer to the pairs than their own spread


def test_history_0_relabels_no_pull_and_needs_no_relabelling_from_the_env():
    """``history: 0``: the refits of an env that reports its success but no relabelling (a task from outside the
    package). Until the first refit the run is the run without hindsight, parameter for parameter; the refit then
    happens on the solving pulls, as with relabelling."""
    settings = {"refit_every": 64, "refit_start": 48, "refit_steps": 300, "regression_lr": 1e-2}

    def run(hindsight_kwargs, episodes):
        env = LatentActionWrapper(SuccessOnlyReachEnv(), LinearGenerator())
        model = GenRL(env, seed=0, n_steps=16, device="cpu", hindsight_kwargs=hindsight_kwargs)
        return model.learn(episodes)

    with pytest.raises(ValueError, match=r"this env's info has no such key \(history: 0 relabels no pull"):
        run(settings, 16)  # relabelling asked for (history 1), which this env cannot give
    plain, refitted = run(None, 32), run({"history": 0, **settings}, 32)
    assert refitted.rollout_buffer_kwargs == {"success": True, "relabel": False}
    assert refitted.logger.name_to_value["train/hindsight_pulls"] == 0
    for ours, theirs in zip(refitted.policy.parameters(), plain.policy.parameters(), strict=True):
        th.testing.assert_close(ours, theirs, rtol=0, atol=0)
    refitted = run({"history": 0, **settings}, 48)
    contexts, actions = (th.cat(part) for part in zip(*refitted.refits.solved, strict=True))
    assert refitted.logger.name_to_value["train/refit_pairs"] == len(actions) > 0
    with th.no_grad():
        error = (refitted.policy.get_distribution(contexts).distribution.mean - actions).pow(2).mean().item()
    assert error < 0.5 * actions.var(0).mean().item()  # closer to the pairs than their own spread


def test_history_0_joins_the_kept_pulls_alone_and_regresses_on_them(trained):
    policy = trained.policy
    hindsight = HindsightRelabelling(policy, history=0, regression_steps=200, regression_lr=1e-2, regression_batch_size=4)
    played = (th.randn(8, 2), th.randn(8, 2), th.randn(8), th.randn(8))
    relabelled = _filled(trained, _relabel_infos(CONTEXTS, REWARDS)).relabelled_pulls()
    joined, fraction = hindsight.extend_batch(played, relabelled, 0.0, 1.0)
    assert fraction == 0.0 and all(part is original for part, original in zip(joined, played, strict=True))
    assert hindsight.regress() == []  # nothing kept
    kept = KeptPulls(trained.observation_space, trained.action_space, "cpu")
    contexts = th.tensor([CONTEXTS[i] for i in INSIDE], dtype=th.float32)
    targets = th.tensor([[1.0, -1.0], [0.5, 0.5], [-1.0, 0.0], [0.0, 1.5]])
    kept.keep(contexts, targets, th.zeros(4))
    hindsight.kept_pulls = kept
    joined, fraction = hindsight.extend_batch(played, relabelled, 0.0, 1.0)
    assert fraction == 0.5 and len(hindsight.memory) == 0  # the 4 kept pulls, none of the 4 relabelled
    th.testing.assert_close(joined[0][8:], contexts, rtol=0, atol=0)
    losses = hindsight.regress()
    with th.no_grad():
        after = (policy.get_distribution(contexts).distribution.mean - targets).abs().max().item()
    assert len(losses) == 200 and after < 0.1


class _NanHindsightEnv(HindsightReachEnv):
    """HindsightReachEnv whose relabelled pulls have the reward NaN (the played pulls' rewards are finite)."""

    def hindsight(self, info):
        return np.asarray(info["reached"], dtype=np.float32), float("nan")


def test_a_non_finite_relabelled_reward_is_refused_where_it_enters_genrl(trained):
    """A relabelled pull's reward enters GenRL through the pulls' infos: a NaN there is refused at the first pull (it
    used to be taken in, and the E-step's step and KL stayed 0 at every iteration, without a word)."""
    model = GenRL(_NanHindsightEnv(), LinearGenerator(), seed=0, n_steps=16, hindsight_kwargs={})
    with pytest.raises(ValueError, match=r"info\['hindsight'\] holds the relabelled reward nan, not one finite number"):
        model.learn(32)
    assert model.num_timesteps == 1
    buffer = _buffer(trained)
    for bad in ((np.zeros(2), np.array([0.0, 1.0])), (np.zeros(2), "0"), (np.zeros(2), float("inf"))):
        with pytest.raises(ValueError, match=r"info\['hindsight'\] holds the relabelled reward"):
            buffer.add_infos([{"hindsight": bad}])
    with pytest.raises(ValueError, match=r"info\['hindsight'\] must be \(context, reward\) or None"):
        buffer.add_infos([{"hindsight": np.zeros(2)}])


def test_a_goal_env_whose_compute_reward_gives_nan_for_a_relabelled_goal_is_refused_naming_compute_reward():
    from test_fetch_goal_api import PointGoalEnv

    class NanForOtherGoals(PointGoalEnv):  # finite for the episode's own goal, NaN for a relabelled one
        def compute_reward(self, achieved_goal, desired_goal, info):
            reward = super().compute_reward(achieved_goal, desired_goal, info)
            return reward if np.array_equal(desired_goal, self.goal) else np.full_like(reward, np.nan)

    model = GenRL(LatentActionWrapper(NanForOtherGoals(), LinearGenerator()), n_steps=8, seed=0, hindsight_kwargs={})
    with pytest.raises(
        ValueError,
        match=r"NanForOtherGoals.compute_reward\(achieved_goal, desired_goal, info\) returned the non-finite reward nan "
        r"for the achieved goal .* \(a relabelled pull of hindsight\)",
    ):
        model.learn(16)
    assert model.num_timesteps == 0


def test_hindsight_is_a_rollout_buffer_class_in_sb3s_slot_with_no_private_method_of_sb3_overridden():
    """As SB3's HER is a buffer class given by one argument: hindsight_kwargs puts HindsightRolloutBuffer in SB3's
    rollout_buffer_class slot (storing the pulls' success for the refits), and GenRL overrides neither SB3's private
    _update_info_buffer nor collect_rollouts to get the infos there (it did both)."""
    env = LatentActionWrapper(SuccessReachEnv(), LinearGenerator())
    model = GenRL(env, seed=0, n_steps=8, hindsight_kwargs={"refit_every": 16})
    assert model.rollout_buffer_class is HindsightRolloutBuffer and type(model.rollout_buffer) is HindsightRolloutBuffer
    assert model.rollout_buffer_kwargs == {"success": True, "relabel": True} and model.rollout_buffer.success
    assert "_update_info_buffer" not in GenRL.__dict__ and "collect_rollouts" not in GenRL.__dict__
    model.learn(16)
    assert len(model.refits.solved) == 2 and model.logger.name_to_value["train/hindsight_pulls"] > 0
    assert type(GenRL(env, seed=0).rollout_buffer) is not HindsightRolloutBuffer  # no hindsight: SB3's, checking rewards


def test_the_buffer_stores_each_pulls_relabelling_in_its_own_row_with_several_envs():
    """Three envs, four steps: each relabelled pull keeps the latent action it was played with, and the relabelled and
    solving pulls come step by step (the envs of a step in order), recomputed here from what was added."""
    space = gym.spaces.Box(-0.8, 0.8, (2,), np.float32)
    buffer = HindsightRolloutBuffer(4, space, gym.spaces.Box(-3, 3, (2,), np.float32), device="cpu", n_envs=3, success=True)
    rng = np.random.default_rng(0)
    expected, solving = [], []
    for step in range(4):
        contexts = rng.uniform(-1, 1, (3, 2)).astype(np.float32)  # some outside the box: left out
        actions = rng.normal(0, 2, (3, 2)).astype(np.float32)
        infos = []
        for env_index in range(3):
            relabel = (step + env_index) % 3 != 0
            infos.append({"hindsight": (contexts[env_index], -float(step)) if relabel else None, "is_success": env_index == 1})
            if relabel and np.all(np.abs(contexts[env_index]) <= 0.8):
                expected.append((contexts[env_index], actions[env_index], -float(step)))
        solving.append(np.clip(actions[1], -3, 3))
        buffer.add_infos(infos)
        buffer.add(rng.normal(size=(3, 2)), actions, np.zeros(3), np.ones(3), th.zeros(3, 1), th.zeros(3))
    contexts, actions, rewards = buffer.relabelled_pulls()
    assert 0 < len(expected) < 8
    np.testing.assert_array_equal(contexts.numpy(), np.array([pull[0] for pull in expected]))
    np.testing.assert_array_equal(actions.numpy(), np.array([pull[1] for pull in expected]))
    np.testing.assert_array_equal(rewards.numpy(), np.array([pull[2] for pull in expected], np.float32))
    np.testing.assert_array_equal(buffer.solving_pulls()[1].numpy(), np.array(solving))
    next(buffer.get(batch_size=None))  # SB3 flattens its own arrays; the relabelling is read as it was stored
    np.testing.assert_array_equal(buffer.relabelled_pulls()[1].numpy(), np.array([pull[1] for pull in expected]))
    with pytest.raises(ValueError, match="hindsight_kwargs relabels Box contexts"):
        HindsightRolloutBuffer(4, gym.spaces.Dict({"goal": space}), space)


class _Counter(BaseCallback):
    def _on_step(self) -> bool:
        self.steps = getattr(self, "steps", 0) + 1
        return True


def test_learn_hands_the_infos_to_the_buffer_beside_the_users_callbacks_of_every_form():
    env = LatentActionWrapper(HindsightReachEnv(), LinearGenerator())
    calls = []
    for callback in (None, _Counter(), [_Counter(), _Counter()], lambda local, global_: calls.append(1) or True):
        model = GenRL(env, seed=0, n_steps=8, hindsight_kwargs={})
        model.learn(16, callback=callback)
        assert model.logger.name_to_value["train/hindsight_pulls"] > 0
        for counter in callback if isinstance(callback, list) else [callback]:
            assert not isinstance(counter, _Counter) or counter.steps == 16
    assert len(calls) == 16


def test_the_kl_bound_by_success_is_target_kl_times_the_batchs_failed_share_at_least_the_floor(monkeypatch):
    """With success_kl_floor, every TRPO E-step gets target_kl * max(failed share of its batch, floor), the share
    counted here from the successes the env reported (a callback's view of each pull's info); without it, target_kl."""
    bounds = []
    trpo = genrl_module.trpo_e_step

    def recording(*args, target_kl, **kwargs):
        bounds.append(target_kl)
        return trpo(*args, target_kl=target_kl, **kwargs)

    monkeypatch.setattr(genrl_module, "trpo_e_step", recording)

    class Successes(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.batches: list[list[bool]] = []

        def _on_rollout_start(self) -> None:
            self.batches.append([])

        def _on_step(self) -> bool:
            self.batches[-1] += [bool(info["is_success"]) for info in self.locals["infos"]]
            return True

    hindsight = {"history": 0, "refit_every": 32, "refit_steps": 5}
    env = LatentActionWrapper(SuccessOnlyReachEnv(), LinearGenerator())
    seen = Successes()
    model = GenRL(env, seed=0, n_steps=16, n_em_iterations=2, target_kl=0.02, success_kl_floor=0.6, hindsight_kwargs=hindsight)
    model.learn(16 * 12, callback=seen)
    failed = [1.0 - float(np.mean(batch)) for batch in seen.batches]
    expected = [0.02 * max(share, 0.6) for share in failed for _ in range(2)]
    assert bounds == pytest.approx(expected, rel=1e-12)
    assert min(failed) < 0.6 < max(failed)  # batches at the floor and above it
    bounds.clear()
    GenRL(env, seed=0, n_steps=16, n_em_iterations=2, target_kl=0.02, hindsight_kwargs=hindsight).learn(16 * 4)
    assert bounds == [0.02] * 8
