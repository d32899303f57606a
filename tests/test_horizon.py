"""The horizon of a task's demonstrations, read from its expert (sb3_genrl.envs.demonstrations.expert_horizon)."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from sb3_genrl.envs.demonstrations import describe_horizon, expert_horizon

STEPS = 40


class WindowEnv(gym.Env):
    """Succeeds exactly from step ``first`` to step ``last`` (1-based); with ``late``, a reset whose seed draws an odd
    number succeeds only from step ``late`` on: every answer of :func:`expert_horizon` can be worked out by hand."""

    metadata = {"render_modes": []}

    def __init__(self, first: int = 8, last: int = 30, late: int | None = None) -> None:
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.first, self.last, self.late = first, last, late

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.odd = bool(self.np_random.integers(2))
        self.t = 0
        return np.array([float(self.odd)], dtype=np.float32), {}

    def step(self, action):
        self.t += 1
        first = self.late if (self.late is not None and self.odd) else self.first
        return np.array([float(self.odd)], dtype=np.float32), 0.0, False, False, {"is_success": first <= self.t <= self.last}


def idle_expert(observation):
    return np.zeros(1)


gym.register("TestHorizon/Window-v0", entry_point=WindowEnv, max_episode_steps=STEPS)
gym.register(
    "TestHorizon/Late-v0", entry_point=WindowEnv, kwargs={"first": 5, "last": STEPS, "late": 12}, max_episode_steps=STEPS
)


def window(**kwargs):
    return lambda: gym.make("TestHorizon/Window-v0", **kwargs)


def test_the_horizon_is_the_first_at_which_the_success_has_held_for_the_last_fifth_of_it():
    # success from step 8 to 30: h = 9 is the first whose last fifth (steps ceil(0.8 h) = 8 .. 9) all succeed
    found = expert_horizon(window(first=8, last=30), idle_expert, resets=10)
    assert (found["horizon"], found["settled"], found["success"], found["best"], found["best_step"]) == (9, True, 1.0, 1.0, 8)
    assert found["success_by_step"] == [0.0] * 7 + [1.0] * 23 + [0.0] * 10 and found["max_steps"] == STEPS
    assert describe_horizon(found) == "where the expert's success settles (1.00 of 10 seeded resets; its best 1.00 at step 8)"
    # no window: the first step at which it succeeds; a longer one: ceil(0.5 h) >= 8 first at h = 15
    assert expert_horizon(window(), idle_expert, resets=10, settled_share=0.0)["horizon"] == 8
    assert expert_horizon(window(), idle_expert, resets=10, settled_share=0.5)["horizon"] == 15


def test_the_horizon_waits_for_the_late_resets_within_the_tolerance():
    # odd resets succeed from step 12 on, even ones from step 5: the success is the even share from 5 to 11, then 1
    found = expert_horizon(window(first=5, last=STEPS, late=12), idle_expert, resets=100)
    by_step = np.array(found["success_by_step"])
    share = by_step[4]
    assert 0.2 < share < 0.8 and np.all(by_step[4:11] == share) and np.all(by_step[11:] == 1.0)
    assert found["horizon"] == 14  # ceil(0.8 h) >= 12 first at h = 14
    # a tolerance above the odd share: the even resets' start is near enough to the best
    loose = expert_horizon(window(first=5, last=STEPS, late=12), idle_expert, resets=100, tolerance=1.0 - share + 0.01)
    assert loose["horizon"] == 6  # ceil(0.8 h) >= 5 first at h = 6


def test_a_success_that_never_settles_gives_the_horizon_whose_last_fifth_succeeds_most_and_says_so():
    # success at steps 10 and 11 only: no window of a fifth of the horizon fits in it; the window of h = 11 (steps
    # 9 to 11) succeeds on 2 of its 3 steps, as h = 12's (10 to 12), and every other on fewer: the shorter, 11
    found = expert_horizon(window(first=10, last=11), idle_expert, resets=5)
    assert (found["horizon"], found["settled"], found["best"], found["success"]) == (11, False, 1.0, 1.0)
    assert "success never settles, but holds best over the horizon's last fifth" in describe_horizon(found)
    assert expert_horizon(window(first=10, last=11), idle_expert, resets=5, max_steps=25)["horizon"] == 11


def test_an_expert_that_never_succeeds_or_bad_settings_are_refused_naming_them():
    with pytest.raises(ValueError, match="succeeded on none of 4 seeded resets within 40 steps"):
        expert_horizon(window(first=STEPS + 1, last=STEPS + 1), idle_expert, resets=4)
    with pytest.raises(ValueError, match="settled_share must be below 1"):
        expert_horizon(window(), idle_expert, settled_share=1.0)
    with pytest.raises(ValueError, match="resets"):
        expert_horizon(window(), idle_expert, resets=0)
    with pytest.raises(ValueError, match="no expert of the package's"):
        expert_horizon(window())


def test_worker_processes_find_the_same_horizon_as_one_process():
    # the resets are played in two worker processes, in chunks, and read back in their order: the same success by step
    one = expert_horizon("TestHorizon/Late-v0", idle_expert, resets=30, n_threads=1)
    two = expert_horizon("TestHorizon/Late-v0", idle_expert, resets=30, n_threads=2)
    assert two == one and one["horizon"] == 14 and 0.0 < one["success_by_step"][4] < 1.0  # both kinds of reset drawn
