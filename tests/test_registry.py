"""The task registry: lookups and errors, a toy third task run through ``genrl demos``, ``train-generator`` and
``train-policy``, and no task name outside the task modules and the registry."""

from __future__ import annotations

import json
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from sb3_genrl.envs import TASKS, TaskSpec, get_task, register_task
from sb3_genrl.envs.arm import task_mjcf
from sb3_genrl.envs.base import ArmTaskEnv
from sb3_genrl.envs.motions import bump

from sb3_genrl.cli import main
from sb3_genrl.data import dataset_info, load_actions

REACH_HORIZON = 10
REACH_LOW, REACH_HIGH = np.array([0.1, -0.5]), np.array([0.9, 0.5])
_SENSORS = '<clock/><framepos objtype="site" objname="tip"/><framelinvel objtype="site" objname="tip"/>' + "".join(
    f'<jointvel joint="joint{i}"/>' for i in range(1, 8)
)


class ReachEnv(ArmTaskEnv):
    """A toy task: tilt the arm so that the tip of a short rod ends above the goal (the tip is the "object")."""

    horizon = REACH_HORIZON
    settle_steps = 0
    worst_reward = -3.0
    goal_low, goal_high = REACH_LOW, REACH_HIGH

    def _mjcf(self) -> str:
        return task_mjcf(
            name="reach",
            tool='<geom type="capsule" fromto="0 0 0 0 0 0.1" size="0.01"/><site name="tip" pos="0 0 0.1" size="0.01"/>',
            world='<geom name="floor" type="plane" size="3 3 0.1" material="grid"/>'
            '<body name="goal" mocap="true" pos="0.5 0 0.001"><geom type="cylinder" '
            'size="0.03 0.001" contype="0" conaffinity="0"/></body>',
            sensors=_SENSORS,
            camera='<camera name="overview" pos="0 -3 2" xyaxes="1 0 0 0 0.55 0.83"/>',
        )

    def home_qpos(self) -> np.ndarray:
        return np.zeros(7)

    def sample_goal(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(self.goal_low, self.goal_high)

    def _place_objects(self) -> None:
        pass

    def _outcome(self, rows: np.ndarray, goal: np.ndarray) -> tuple[float, dict]:
        reached = rows[-1, 1:3].copy()
        distance = float(np.linalg.norm(reached - goal))
        return -distance, {"reached": reached, "distance": distance}


def _in_box(points: np.ndarray) -> np.ndarray:
    return np.all((points >= REACH_LOW) & (points <= REACH_HIGH), axis=1)


def _tilt(rng: np.random.Generator) -> np.ndarray:
    """The toy expert: turn the base and tilt the shoulder forward."""
    motion = np.zeros((REACH_HORIZON, 7))
    motion[:, 0] = bump(REACH_HORIZON, 0, 8, rng.uniform(-0.4, 0.4))
    motion[:, 1] = bump(REACH_HORIZON, 0, 8, rng.uniform(0.3, 0.7))
    return motion


REACH = TaskSpec(
    name="reach",
    env_id="Toy/Reach-v0",
    env_class=ReachEnv,
    horizon=REACH_HORIZON,
    goal_low=REACH_LOW,
    goal_high=REACH_HIGH,
    in_goal_region=_in_box,
    cell_size=0.1,
    sample_expert=_tilt,
    perturbation_scales=np.full(7, 0.02),
    is_valid=lambda info: info["distance"] >= 0,
)


@pytest.fixture
def reach_task():
    register_task(REACH)
    yield REACH
    TASKS.pop(REACH.name)
    gym.registry.pop(REACH.env_id)


def test_lookups_and_errors():
    assert {"hockey", "basketball"} <= set(TASKS)
    for name, spec in TASKS.items():
        assert get_task(name) is spec and get_task(spec.env_id) is spec and get_task(spec) is spec
        assert gym.spec(spec.env_id).max_episode_steps == spec.horizon == getattr(spec.make_env(), "horizon", spec.horizon)
    with pytest.raises(ValueError, match=r"unknown task 'golf'; expected one of \['basketball', .*'hockey'"):
        get_task("golf")
    with pytest.raises(ValueError, match="already registered as 'hockey'"):
        register_task(TaskSpec(**{**vars(REACH), "name": "hockey"}))
    with pytest.raises(ValueError, match="already belongs to task 'hockey'"):
        register_task(TaskSpec(**{**vars(REACH), "env_id": TASKS["hockey"].env_id}))
    with pytest.raises(ValueError, match="horizon 12 differs from ReachEnv.horizon 10"):
        TaskSpec(**{**vars(REACH), "horizon": 12})
    with pytest.raises(ValueError, match=r"perturbation_scales must have shape \(7,\)"):
        TaskSpec(**{**vars(REACH), "perturbation_scales": np.ones(6)})
    for count in (0, 2.5, True):
        with pytest.raises(ValueError, match=f"quickstart_demo_episodes must be an integer >= 1, got {count!r}"):
            TaskSpec(**{**vars(REACH), "quickstart_demo_episodes": count})
    assert "reach" not in TASKS and REACH.env_id not in gym.registry  # nothing half-registered


def test_toy_task_through_the_cli(reach_task, tmp_path, capsys):
    data, generator, run = tmp_path / "demos", tmp_path / "vae.pt", tmp_path / "run"
    assert gym.make(REACH.env_id).spec.max_episode_steps == REACH_HORIZON
    assert (
        main(["demos", "--task", "reach", "--episodes", "40", "--out", str(data), "--threads", "1", "--no-progress-bar"]) == 0
    )
    info = dataset_info(data)
    assert (info["task"], info["env_id"], info["horizon"], info["episodes"]) == ("reach", REACH.env_id, 10, 40)
    actions = load_actions(data, task="reach", horizon=REACH_HORIZON)
    assert actions.shape == (40, REACH_HORIZON, 7)
    # Each action sequence is an expert tilt plus small perturbations: the shoulder moves forward by 0.3-0.7 rad.
    assert np.all((actions[:, :, 1].sum(axis=1) > 0.2) & (actions[:, :, 1].sum(axis=1) < 0.8))
    coverage = json.loads((data / "coverage.json").read_text())
    assert coverage["cells"] == 8 * 10 and coverage["cell_size"] == 0.1  # the 0.8 m x 1.0 m box in 0.1 m cells

    assert (
        main(
            [
                "train-generator",
                "--data",
                str(data),
                "--model",
                "vae",
                "--latent-dim",
                "2",
                "--beta",
                "0.01",
                "--epochs",
                "3",
                "--batch-size",
                "16",
                "--eval-every",
                "3",
                "--device",
                "cpu",
                "--no-progress-bar",
                "--out",
                str(generator),
            ]
        )
        == 0
    )
    from sb3_genrl.generative import load

    assert load(generator, device="cpu").horizon == REACH_HORIZON

    assert (
        main(
            [
                "train-policy",
                "--task",
                "reach",
                "--generator",
                str(generator),
                "--episodes",
                "16",
                "--batch-episodes",
                "8",
                "--device",
                "cpu",
                "--no-progress-bar",
                "--out",
                str(run),
            ]
        )
        == 0
    )
    summary = json.loads((run / "summary.json").read_text())
    assert (summary["task"], summary["episodes"], summary["iterations"]) == ("reach", 16, 2)
    from sb3_genrl.genrl import GenRL
    from sb3_genrl.run import evaluate_on_goals

    model = GenRL.load(run / "genrl_policy.zip", device="cpu")
    goals, rewards, infos = evaluate_on_goals(model, "reach", goals=4, seed=1)
    assert model.generator.decode(np.zeros((1, 2), dtype=np.float32)).shape == (1, REACH_HORIZON, 7)
    np.testing.assert_allclose(rewards, [-np.linalg.norm(i["reached"] - g) for i, g in zip(infos, goals, strict=True)])
    assert "GenRL on reach" in capsys.readouterr().out


def test_task_names_only_in_the_task_modules_and_the_registry():
    root = Path(__file__).resolve().parents[1]
    allowed = {Path("envs/__init__.py")} | {
        Path(f"envs/{name}.py") for name in ("hockey", "basketball", "fetch", "fetch_tasks")
    }
    pattern = re.compile(r'"(?:{})"'.format("|".join(TASKS)))
    found = [
        str(path.relative_to(root))
        for folder in ("sb3_genrl", "envs", "baselines")
        for path in sorted((root / folder).rglob("*.py"))
        if path.relative_to(root) not in allowed and pattern.search(path.read_text())
    ]
    assert found == []


def test_task_settings_come_from_genrl_yml(reach_task):
    from sb3_genrl.hyperparams import load_hyperparams
    from sb3_genrl.study.quickstart import DEFAULT_BATCH_EPISODES, DEFAULT_POLICY_EPISODES, task_settings

    entry = load_hyperparams("genrl", "GenRL/Basketball-v0")
    episodes, batch_episodes, kwargs = task_settings("basketball")
    assert (episodes, batch_episodes) == (entry["n_timesteps"], entry["n_steps"]) == (20000, 16)
    assert kwargs == {key: value for key, value in entry.items() if key not in ("n_timesteps", "n_steps", "env_wrapper")}
    assert task_settings("GenRL/Basketball-v0") == task_settings("basketball")  # by name or Gymnasium id
    # a task of its own without an entry: GenRL's defaults (the paper's 3000 episodes, 64 per iteration)
    assert task_settings("reach") == (DEFAULT_POLICY_EPISODES, DEFAULT_BATCH_EPISODES, {}) == (3000, 64, {})


def with_genrl_entry(monkeypatch: pytest.MonkeyPatch, env_id: str, entry: dict) -> None:
    """``genrl.yml`` as if it also held ``entry`` for ``env_id``."""
    from sb3_genrl import hyperparams

    entries = hyperparams._entries("genrl") | {env_id: entry}
    monkeypatch.setattr(hyperparams, "_entries", lambda algo: entries if algo == "genrl" else {})


def test_train_policy_takes_the_tasks_genrl_settings(reach_task, tmp_path, monkeypatch):
    data, generator = tmp_path / "demos", tmp_path / "vae.pt"
    assert (
        main(["demos", "--task", "reach", "--episodes", "16", "--out", str(data), "--threads", "1", "--no-progress-bar"]) == 0
    )
    assert (
        main(
            [
                "train-generator",
                "--data",
                str(data),
                "--model",
                "vae",
                "--latent-dim",
                "2",
                "--beta",
                "0.01",
                "--epochs",
                "1",
                "--batch-size",
                "16",
                "--eval-every",
                "1",
                "--device",
                "cpu",
                "--no-progress-bar",
                "--out",
                str(generator),
            ]
        )
        == 0
    )
    tuned = {"target_kl": 0.02, "value_history": 2, "policy": "ContextStdPolicy", "policy_kwargs": {"net_arch": [16, 16]}}
    with_genrl_entry(monkeypatch, REACH.env_id, {"n_timesteps": 3000, "n_steps": 4, **tuned})
    settings, iterations = {}, {}
    for name, extra in (
        ("task", ["--batch-episodes", "8"]),
        ("library", ["--batch-episodes", "8", "--library-defaults"]),
        ("task_batch", []),
    ):
        assert (
            main(
                [
                    "train-policy",
                    "--task",
                    "reach",
                    "--generator",
                    str(generator),
                    "--episodes",
                    "16",
                    "--n-envs",
                    "1",  # one env: the episodes per iteration are n_steps
                    "--device",
                    "cpu",
                    "--no-progress-bar",
                    "--out",
                    str(tmp_path / name),
                    *extra,
                ]
            )
            == 0
        )
        summary = json.loads((tmp_path / name / "summary.json").read_text())
        settings[name], iterations[name] = summary["genrl_settings"], summary["iterations"]
    # Without --batch-episodes the task's episodes per iteration apply; --batch-episodes overrides them.
    assert (settings["task_batch"]["n_steps"], iterations["task_batch"]) == (4, 4)
    assert settings["task_batch"] == settings["task"] | {"n_steps": 4, "batch_size": 4} and iterations["task"] == 2
    # Each run records every GenRL hyperparameter in effect: the task's where it sets them, GenRL's defaults elsewhere.
    assert settings["task"] == settings["library"] | tuned
    assert settings["library"]["target_kl"] == 0.01 and settings["library"]["value_history"] == 1
    assert settings["library"]["n_steps"] == 8 and settings["library"]["max_log_std_change"] is None
    assert "seed" not in settings["library"] and "device" not in settings["library"]
    assert "policy" not in settings["library"]  # the default policy is not named, as in the records made before
    from sb3_genrl import GenRL
    from sb3_genrl.genrl.policies import ContextStdPolicy

    assert isinstance(GenRL.load(tmp_path / "task" / "genrl_policy.zip", device="cpu").policy, ContextStdPolicy)


def test_the_arms_workflows_run_on_the_arms_tasks_only(tmp_path, cli):
    # The scripted motions' showcase, the baselines, the video and the study are the arm tasks' machinery: with the
    # Fetch tasks registered (the robotics extra), "every task" means the arm's, and a Fetch task is refused at once.
    from sb3_genrl.envs import TASKS, arm_tasks

    from sb3_genrl.showcase import play_scripted
    from sb3_genrl.study import run_study

    assert arm_tasks() == ("hockey", "basketball")
    fetch = [name for name in TASKS if name not in arm_tasks()]
    assert fetch, "the test command installs the robotics extra: the Fetch tasks must be registered"
    (tmp_path / "g.pt").write_bytes(b"")  # an input that exists: only --task is wrong
    for command in (
        ("play", "--out", tmp_path / "p"),
        ("study", "--scale", "smoke", "--out", tmp_path / "s"),
        ("video", "--generator", tmp_path / "g.pt", "--out", tmp_path / "v.gif"),
        ("compare", "--runs", tmp_path, "--out", tmp_path / "c"),
    ):
        code, _, err = cli(*command, "--task", fetch[0])
        assert code == 2 and f"invalid choice: '{fetch[0]}'" in err, (command, err)
    with pytest.raises(ValueError, match=f"unknown task '{fetch[0]}' for the study"):
        run_study(fetch[0], "smoke", tmp_path / "s")
    with pytest.raises(ValueError, match="the scripted motions are shown for the tasks on the package's arm"):
        play_scripted(tmp_path / "p", tasks=(fetch[0],))
    assert not any(path.exists() for path in (tmp_path / "p", tmp_path / "s", tmp_path / "c", tmp_path / "v.gif"))
