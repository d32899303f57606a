"""Several pulls per context: each context played ``pulls`` times, and each pull's advantage taken against the others.

GenRL's advantage is ``A = r - V(s0)``, with the value function fitted to one pull per context. On a bandit whose limit
is known (docs/guide/search.md), that baseline is what stops the search: at a context, its error is a bias of the one
pull's advantage, larger than the differences of reward within the policy's spread near the answer, and an exact
baseline takes the policy's mean most of the way to the generator's limit with the same pulls.

A context is a seeded reset, and GenRL's episodes are open loop, so a context can be played again: with
``GenRL(pulls_per_context=K)``, the episodes of an iteration come in groups of ``K`` pulls from one reset seed, and a
pull's advantage is its reward minus the mean reward of the other ``K - 1`` pulls of its group (the leave-one-out
baseline of Kool et al., 2019, "Buy 4 REINFORCE samples, get a baseline for free!", and of GRPO's groups). That
baseline is unbiased and needs no value function; under a sparse reward, a group where one pull succeeds and another
fails gives exactly the signal that moves the mean towards the success.

The groups follow the run's pulls in SB3's order (a rollout's step ``t`` holds the envs ``0 .. n_envs - 1``): pull
``p = episode * n_envs + env`` belongs to group ``p // K``, whose reset seed :func:`context_seed` derives from the
run's root seed and the group. Each env's :class:`~sb3_genrl.LatentActionWrapper` resets with
:class:`ContextSeeds` (``set_reset_seeds``), so the groups are the same with one env, several, env processes or the
batched fast path, and a stopped run resumes into the same groups.
"""

from __future__ import annotations

import numpy as np

SEED_BOUND = 2**31  # reset seeds below it, as the recorders draw them


def context_seed(root: int, group: int) -> int:
    """The reset seed of a group of pulls: a hash of the run's ``root`` seed and the ``group``'s index."""
    return int(np.random.SeedSequence([int(root), int(group)]).generate_state(1, np.uint64)[0] % SEED_BOUND)


class ContextSeeds:
    """The reset seed of each episode of one env of a run whose contexts come in groups of ``pulls``: episode ``k`` of
    env ``index`` (of ``n_envs``) is pull ``k * n_envs + index`` of the run, and resets with its group's
    :func:`context_seed`.

    :param root: the run's root seed
    :param pulls: pulls per context
    :param index: the env's index in the VecEnv
    :param n_envs: envs of the VecEnv
    """

    def __init__(self, root: int, pulls: int, index: int, n_envs: int) -> None:
        self.root, self.pulls, self.index, self.n_envs = int(root), int(pulls), int(index), int(n_envs)

    def __call__(self, episode: int) -> int:
        return context_seed(self.root, (int(episode) * self.n_envs + self.index) // self.pulls)

    def __repr__(self) -> str:
        return f"ContextSeeds(root={self.root}, pulls={self.pulls}, index={self.index}, n_envs={self.n_envs})"


def leave_one_out_advantages(rewards: np.ndarray, pulls: int) -> np.ndarray:
    """Each pull's reward minus the mean reward of the other pulls of its group.

    :param rewards: a rollout's rewards, ``(n_steps, n_envs)`` as SB3's rollout buffer holds them; the groups are
        consecutive in the row-major order (step by step, the envs of a step in order), and ``n_steps * n_envs`` is a
        multiple of ``pulls``
    :param pulls: pulls per group, at least 2
    :return: the advantages, of the shape of ``rewards``
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    if pulls < 2 or rewards.size % pulls:
        raise ValueError(f"groups of {pulls} pulls need a multiple of {pulls} rewards and pulls >= 2, got {rewards.size}")
    groups = rewards.reshape(-1, pulls)
    others = (groups.sum(axis=1, keepdims=True) - groups) / (pulls - 1)
    return (groups - others).reshape(rewards.shape).astype(np.float32)
