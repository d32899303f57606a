"""The making of demonstrations, for every kind of task (learning from them is the algorithm's:
:class:`sb3_genrl.genrl.demonstrations.DemonstrationCallback`).

- :mod:`sb3_genrl.envs.demonstrations.arm`: the arm tasks' (hockey, basketball) perturbed expert motions, simulated in
  batches and kept when valid (:func:`make_demonstrations`, :func:`perturbation`); a task with its own maker (a
  :class:`~sb3_genrl.envs.spec.TaskSpec` with ``demonstrations``) is written through it too.
- :mod:`sb3_genrl.envs.demonstrations.fetch`: the Fetch tasks' scripted expert with perturbations, played through
  Gymnasium-Robotics' envs (:func:`make_arrays`, what ``make_demonstrations`` writes for them), and the
  open-loop success of the expert, of a generator's reconstructions and of a policy.
- :mod:`sb3_genrl.envs.demonstrations.recorder`: any episodic Gymnasium env with an expert callable, recorded closed
  loop with smooth perturbations and kept when its open-loop replay succeeds (:func:`record_demonstrations`).
- :mod:`sb3_genrl.envs.demonstrations.horizon`: the horizon a task's demonstrations need, the shortest at which its
  expert's success settles (:func:`expert_horizon`).
- :mod:`sb3_genrl.envs.demonstrations.tasks`: the one entry of every task (:func:`task_demonstrations`): its own maker
  where it has one, else its expert's recorded demonstrations.
- :mod:`sb3_genrl.envs.demonstrations.replay`: any episodic Gymnasium env with a dataset of actions and their reset
  seeds (Minari, or arrays), each episode kept when its open-loop replay succeeds (:func:`replay_demonstrations`).

Each writes a Minari dataset (:func:`sb3_genrl.data.write_dataset`) whose episodes depend on the seed only.
"""

from sb3_genrl.envs.demonstrations.arm import (
    is_valid,
    make_demonstrations,
    perturbation,
    refuse_existing_output,
    sample_trajectories,
    within_limits,
)
from sb3_genrl.envs.demonstrations.fetch import expert_success, make_arrays, play_expert
from sb3_genrl.envs.demonstrations.horizon import describe_horizon, expert_horizon
from sb3_genrl.envs.demonstrations.recorder import (
    BUMP_DURATIONS,
    DEFAULT_NOISE,
    expert_name,
    pad_actions,
    play_episode,
    record_demonstrations,
    smooth_noise,
    write_demonstrations,
)
from sb3_genrl.envs.demonstrations.replay import read_replay_source, replay_demonstrations
from sb3_genrl.envs.demonstrations.tasks import own_maker, task_demonstrations

__all__ = [
    "BUMP_DURATIONS",
    "DEFAULT_NOISE",
    "describe_horizon",
    "expert_horizon",
    "expert_name",
    "expert_success",
    "is_valid",
    "make_arrays",
    "make_demonstrations",
    "own_maker",
    "pad_actions",
    "perturbation",
    "play_episode",
    "play_expert",
    "read_replay_source",
    "record_demonstrations",
    "refuse_existing_output",
    "replay_demonstrations",
    "sample_trajectories",
    "smooth_noise",
    "task_demonstrations",
    "within_limits",
    "write_demonstrations",
]
