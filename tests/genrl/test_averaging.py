"""GenRL's policy averaging (sb3_genrl/genrl/averaging.py) against a brute-force average of the iterates."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import (
    FastReachEnv,
    LinearGenerator,
)
from genrl_test_helpers import GOALS, Recorder

from sb3_genrl import GenRL


class _WeightRecorder(Recorder):
    """The policy's weights after each iteration (recorded before the next rollout, and at the end)."""

    def __init__(self) -> None:
        super().__init__()
        self.weights: list[dict[str, np.ndarray]] = []

    def _record(self) -> None:
        if self.model._n_updates > len(self.weights):
            self.weights.append({k: v.detach().cpu().numpy().copy() for k, v in self.model.policy.named_parameters()})


def test_policy_averaging_is_the_start_corrected_moving_average_and_acts(tmp_path):
    from sb3_genrl.run.loading import load_policy

    recorder, decay = _WeightRecorder(), 0.7
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, policy_averaging=decay)
    model.learn(6 * 16, callback=recorder)
    assert len(recorder.weights) == 6
    # Brute force: sum_i d^(n-i) theta_i / sum_i d^(n-i) over the iterates theta_1..6 (the initial policy excluded).
    factors = decay ** np.arange(5, -1, -1)
    for name, value in model.policy_average.named_parameters():
        expected = sum(f * w[name] for f, w in zip(factors, recorder.weights, strict=True)) / factors.sum()
        np.testing.assert_allclose(value.detach().cpu().numpy(), expected, rtol=1e-5, atol=1e-6)
    average_weight = model.policy_average.action_net.weight.detach().cpu().numpy()
    assert not np.allclose(average_weight, recorder.weights[-1]["action_net.weight"])
    # predict acts with the average, here and after saving and loading (with SB3's loader and without unpickling).
    averaged = model.policy_average.predict(GOALS, deterministic=True)[0]
    np.testing.assert_allclose(model.predict(GOALS, deterministic=True)[0], averaged)
    assert not np.allclose(model.policy.predict(GOALS, deterministic=True)[0], averaged)
    model.save(tmp_path / "model.zip")
    loaded = GenRL.load(tmp_path / "model.zip", generator=LinearGenerator())
    np.testing.assert_allclose(loaded.predict(GOALS, deterministic=True)[0], averaged, rtol=1e-6)
    safe = load_policy(tmp_path / "model.zip", FastReachEnv(), generator=LinearGenerator())
    np.testing.assert_allclose(safe.predict(GOALS, deterministic=True)[0], averaged, rtol=1e-6)
    # Without averaging nothing changes: predict is the policy's own.
    plain = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16)
    assert plain.policy_average is None and "policy_average" not in plain._get_torch_save_params()[0]
    for bad in (0, 1, 1.5):
        with pytest.raises(ValueError, match=f"policy_averaging must be between 0 and 1 \\(exclusive\\) or None, got {bad}"):
            GenRL(FastReachEnv(), LinearGenerator(), policy_averaging=bad)
