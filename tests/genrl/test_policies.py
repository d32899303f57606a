"""GenRL's policies (sb3_genrl/genrl/policies.py): BoxScaler, the spread's trust region, ContextStdPolicy."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from conftest import (
    FastReachEnv,
    LinearGenerator,
)
from genrl_test_helpers import GOALS, Recorder, box_corners
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.genrl.policies import BoxScaler


def test_box_scaler_on_unbounded_observations_does_not_warn():
    from sb3_genrl.genrl.policies import BoxScaler

    space = gym.make("Reacher-v5").observation_space  # every bound infinite
    mixed = gym.spaces.Box(np.array([-np.inf, 0.0, -2.0], np.float32), np.array([np.inf, np.inf, 2.0], np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scaler = BoxScaler(space)
        observations = th.as_tensor(space.sample()[None])
        th.testing.assert_close(scaler(observations), observations)  # unbounded dimensions pass unchanged
        mixed_scaler = BoxScaler(mixed)
        out = mixed_scaler(th.tensor([[5.0, 3.0, 1.0]]))
    th.testing.assert_close(out, th.tensor([[5.0, 3.0, 0.5]]))


def test_box_scaler_standardises_the_unbounded_dimensions_that_move_and_keeps_the_box_of_the_others():
    space = gym.spaces.Box(
        np.array([-2.0, -np.inf, -np.inf, -np.inf], np.float32), np.array([2.0, np.inf, np.inf, np.inf], np.float32)
    )
    rng = np.random.default_rng(0)
    contexts = np.stack(
        [
            rng.uniform(-2, 2, 500),  # bounded: keeps [-2, 2] -> [-1, 1]
            rng.normal(5.0, 3.0, 500),  # unbounded, moving: standardised
            1.36 + rng.normal(0.0, 1e-5, 500),  # unbounded, barely moving (a start pose): centred only
            rng.normal(-1.0, 0.02, 500),  # unbounded, moving on a smaller scale than the second: standardised
        ],
        axis=1,
    ).astype(np.float32)
    scaler = BoxScaler(space)
    scaler.scale_unbounded(th.as_tensor(contexts))
    features = scaler(th.as_tensor(contexts)).double().numpy()
    x = contexts.astype(np.float64)
    expected = np.stack(
        [
            x[:, 0] / 2.0,
            (x[:, 1] - x[:, 1].mean()) / x[:, 1].std(ddof=1),
            x[:, 2] - x[:, 2].mean(),
            (x[:, 3] - x[:, 3].mean()) / x[:, 3].std(ddof=1),
        ],
        axis=1,
    )
    np.testing.assert_allclose(features, expected, rtol=1e-4, atol=1e-5)
    # all constant: centred only, never divided by zero
    constant = BoxScaler(gym.spaces.Box(-np.inf, np.inf, (2,), np.float32))
    constant.scale_unbounded(th.tensor([[1.0, 2.0], [1.0, 2.0]]))
    th.testing.assert_close(constant(th.tensor([[1.5, 2.0]])), th.tensor([[0.5, 0.0]]))
    for bad, says in (
        (th.zeros((1, 4)), "at least 2 contexts"),
        (th.zeros((5, 3)), "of 4 entries"),
        (th.tensor([[0.0, np.nan, 0.0, 0.0]] * 3), "non-finite"),
    ):
        with pytest.raises(ValueError, match=says):
            BoxScaler(space).scale_unbounded(bad)


class _LogStdRecorder(Recorder):
    """The policy's log-std at the start of every rollout (after every update but the last) and at the end."""

    def __init__(self) -> None:
        super().__init__()
        self.values: list[np.ndarray] = []

    def _record(self) -> None:
        self.values.append(self.model.policy.log_std.detach().cpu().numpy().copy())


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
def test_spread_moves_at_most_max_log_std_change_per_iteration(e_step):
    changes = {}
    for bound in (None, 0.01, 0.0):
        recorder = _LogStdRecorder()
        GenRL(FastReachEnv(), LinearGenerator(), e_step=e_step, seed=0, n_steps=32, max_log_std_change=bound).learn(
            8 * 32, callback=recorder
        )
        changes[bound] = np.abs(np.diff(np.array(recorder.values), axis=0))
        assert len(changes[bound]) == 8
    assert changes[None].max() > 0.02  # unbounded, the spread moves faster than the bound allows
    assert changes[0.01].max() <= 0.01 + 1e-6
    assert changes[0.01].min() >= 0.01 - 1e-6  # and here the spread shrinks as fast as the bound lets it
    assert changes[0.0].max() == 0.0  # 0: the spread stays at log_std_init
    with pytest.raises(
        ValueError,
        match=r"max_log_std_change must be >= 0 \(0: the spread stays as it starts\) or "
        r"None, got -0.1",
    ):
        GenRL(FastReachEnv(), LinearGenerator(), max_log_std_change=-0.1)


def test_limit_log_std_change_is_the_largest_change_over_the_box_by_brute_force():
    from sb3_genrl.genrl.policies import ContextStdPolicy, limit_log_std_change, log_std_parameters

    space = gym.spaces.Box(-2.0, 3.0, (3,), np.float32)
    policy = ContextStdPolicy(
        space, gym.spaces.Box(-3, 3, (4,), np.float32), lambda _: 1e-3, features_extractor_class=BoxScaler
    )
    before = log_std_parameters(policy)
    th.testing.assert_close(before["weight"], th.zeros(4, 3))  # it starts independent of the context
    generator = th.Generator().manual_seed(0)
    corners, inside = box_corners(3), th.rand(1000, 3, generator=generator) * 2 - 1
    change = lambda features, params: features @ params["weight"].T + params["bias"] - before["bias"]  # noqa: E731
    for size, bound in ((0.05, 0.02), (0.001, 0.02)):  # a change beyond the bound, and one within it
        with th.no_grad():
            policy.log_std_net.weight.copy_(size * th.randn(4, 3, generator=generator))
            policy.log_std_net.bias.copy_(before["bias"] + size * th.randn(4, generator=generator))
        unbounded = log_std_parameters(policy)
        limit_log_std_change(policy, before, bound)
        after = log_std_parameters(policy)
        # A linear function's largest size over the box is at one of its corners: brute force over them.
        largest_before = change(corners, unbounded).abs().max().item()
        largest = change(corners, after).abs().max().item()
        assert change(inside, after).abs().max().item() <= largest + 1e-7
        if largest_before <= bound:  # kept as it was
            th.testing.assert_close(after, unbounded)
            continue
        assert largest == pytest.approx(bound, rel=1e-5)  # scaled back exactly to the bound ...
        for name in ("weight", "bias"):  # ... by one factor for the whole change: its direction is kept
            th.testing.assert_close(after[name] - before[name], bound / largest_before * (unbounded[name] - before[name]))


class _ContextStdRecorder(Recorder):
    """The policy's log std at the corners of the context box, at the start of every rollout and at the end."""

    def __init__(self, low: float, high: float) -> None:
        super().__init__()
        self.corners = low + (box_corners(2) + 1) / 2 * (high - low)
        self.values: list[np.ndarray] = []

    def _record(self) -> None:
        with th.no_grad():
            corners = self.corners.to(self.model.device)
            self.values.append(self.model.policy.get_distribution(corners).distribution.stddev.log().cpu().numpy())


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
def test_context_std_policy_spread_depends_on_the_context_within_its_trust_region(e_step, tmp_path):
    from sb3_genrl.genrl.policies import ContextStdPolicy
    from sb3_genrl.run.loading import load_policy

    low, high = FastReachEnv.context_space.low[0], FastReachEnv.context_space.high[0]
    changes = {}
    for bound in (None, 0.01):
        recorder = _ContextStdRecorder(low, high)
        model = GenRL(
            "ContextStdPolicy", FastReachEnv(), LinearGenerator(), e_step=e_step, seed=0, n_steps=32, max_log_std_change=bound
        )
        model.learn(8 * 32, callback=recorder)
        values = np.array(recorder.values)
        np.testing.assert_allclose(values[0], 0.0, atol=1e-7)  # the prior's std at first, for every context
        changes[bound] = np.abs(np.diff(values, axis=0))
    assert isinstance(model.policy, ContextStdPolicy) and not hasattr(model.policy, "log_std")
    assert changes[None].max() > 0.02
    assert changes[0.01].max() <= 0.01 + 1e-6  # at every corner of the box, hence everywhere in it
    assert np.ptp(values[-1], axis=0).max() > 1e-4  # the spread differs between contexts
    # The policy's distributions agree however they are computed, and survive saving and loading.
    observations = th.as_tensor(GOALS, device=model.device)
    actions, _, log_prob = model.policy(observations)
    _, evaluated, entropy = model.policy.evaluate_actions(observations, actions)
    distribution = model.policy.get_distribution(observations)
    th.testing.assert_close(evaluated, log_prob)
    th.testing.assert_close(distribution.log_prob(actions), log_prob)
    th.testing.assert_close(distribution.entropy(), entropy)
    model.save(tmp_path / "model.zip")
    for loaded in (
        GenRL.load(tmp_path / "model.zip", generator=LinearGenerator()),
        load_policy(tmp_path / "model.zip", FastReachEnv(), generator=LinearGenerator(), device=model.device),
    ):
        assert isinstance(loaded.policy, ContextStdPolicy)
        th.testing.assert_close(
            loaded.policy.get_distribution(observations).distribution.stddev, distribution.distribution.stddev
        )
        np.testing.assert_allclose(loaded.predict(GOALS, deterministic=True)[0], model.predict(GOALS, deterministic=True)[0])


def test_context_std_trust_region_needs_a_bounded_context():
    unbounded = DummyVecEnv([lambda: LatentActionWrapper(FastReachEnv(), LinearGenerator())])
    unbounded.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    with pytest.raises(ValueError, match="needs a bounded Box context scaled by BoxScaler"):
        GenRL("ContextStdPolicy", unbounded, max_log_std_change=0.01)
    GenRL("ContextStdPolicy", unbounded)  # without the trust region the spread may depend on any features


class _ImageContextEnv(gym.Env):
    """A one-step env whose context is a 36x36 RGB image."""

    observation_space = gym.spaces.Box(0, 255, (36, 36, 3), dtype=np.uint8)
    action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.np_random.integers(0, 256, (36, 36, 3), dtype=np.uint8), {}

    def step(self, action):
        return self.observation_space.sample(), -float(np.abs(action).mean()), True, False, {}


def test_an_image_context_keeps_sb3s_extractors_and_is_scaled_once():
    from stable_baselines3.common.policies import ActorCriticCnnPolicy
    from stable_baselines3.common.torch_layers import FlattenExtractor, NatureCNN

    cnn = GenRL(ActorCriticCnnPolicy, LatentActionWrapper(_ImageContextEnv(), LinearGenerator()), n_steps=4)
    assert isinstance(cnn.policy.features_extractor, NatureCNN)
    mlp = GenRL(LatentActionWrapper(_ImageContextEnv(), LinearGenerator()), n_steps=4)
    assert isinstance(mlp.policy.pi_features_extractor, FlattenExtractor)
    for value, expected in ((0, 0.0), (255, 1.0)):  # SB3 divides by 255, and nothing rescales it again
        image = th.full((1, 36, 36, 3), value, dtype=th.uint8)
        features = mlp.policy.extract_features(mlp.policy.obs_to_tensor(image.numpy())[0], mlp.policy.pi_features_extractor)
        assert th.all(features == expected)
