"""GenRL in rl-zoo3 (:mod:`sb3_genrl.zoo`): rl-zoo3's own train, enjoy, record_video and optuna study, run in-process
on hockey with a small untrained generator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("rl_zoo3")

from sb3_genrl import GenRL  # noqa: E402
from sb3_genrl.hyperparams import EVAL_GOAL_SEED, TUNING_GOAL_SEED, load_hyperparams  # noqa: E402
from sb3_genrl.zoo.__main__ import main  # noqa: E402

ENV_ID = "GenRL/Hockey-v0"
RUN = Path("genrl") / "GenRL-Hockey-v0_1"


def zoo(*argv: object) -> None:
    assert main([str(arg) for arg in argv]) == 0


def with_generator(generator: str) -> list[str]:
    """rl-zoo3's ``-params`` giving the file's env wrapper another generator file."""
    return ["-params", f"env_wrapper:[{{'sb3_genrl.zoo.latent_action': {{'generator': '{generator}'}}}}]"]


def one_at_a_time(model: GenRL, goals: int, seed: int) -> np.ndarray:
    """An independent evaluation: the goals drawn as the package draws them, each goal's deterministic latent action
    decoded and played alone through the task's fast path."""
    from sb3_genrl.envs import get_task

    env = get_task("hockey").make_env()
    rng = np.random.default_rng(seed)
    rewards = []
    for _ in range(goals):
        goal = env.sample_goal(rng)
        latent, _ = model.predict(goal.astype(np.float32), deterministic=True)
        rewards.append(env.play_trajectories(model.generator.decode(latent[None]), goal[None])[0][0])
    return np.array(rewards)


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory, hockey_generator: str) -> Path:
    """A zoo run of one iteration (32 episodes) of the file's hockey settings, in rl-zoo3's ``logs/`` layout, on one
    torch thread as ``genrl`` runs (another thread count rounds differently)."""
    logs = tmp_path_factory.mktemp("zoo") / "logs"
    zoo(
        "train",
        "--algo",
        "genrl",
        "--env",
        ENV_ID,
        "-n",
        32,
        "--seed",
        3,
        "--eval-freq",
        -1,
        "-f",
        logs,
        "--save-freq",
        32,
        "-tb",
        logs.parent / "tensorboard",
        "--device",
        "cpu",
        "--num-threads",
        1,
        *with_generator(hockey_generator),
    )
    return logs


def test_train_saves_in_rl_zoo3s_layout_with_the_generator_it_used(trained, hockey_generator):
    from sb3_genrl.genrl.generator_files import generator_digest
    from sb3_genrl.zoo.wrapper import load_generator

    run = trained / RUN
    assert (run / "GenRL-Hockey-v0.zip").is_file() and (run / "0.monitor.csv").is_file()
    assert (run / "rl_model_32_steps.zip").is_file()  # --save-freq's checkpoint
    assert any((trained.parent / "tensorboard" / "GenRL-Hockey-v0").glob("*/events.out.tfevents.*"))  # -tb
    config = yaml.load((run / "GenRL-Hockey-v0" / "config.yml").read_text(), Loader=yaml.UnsafeLoader)
    (wrapper,) = config["env_wrapper"]
    assert wrapper == {
        "sb3_genrl.zoo.latent_action": {
            "generator": str(Path(hockey_generator).resolve()),
            "generator_sha256": generator_digest(load_generator(Path(hockey_generator))),
        }
    }
    # the iteration's 32 episodes played together as 32 envs (rl-zoo3 writes a Monitor file per env), the Monitor
    # above the one-step episodes: one row per episode played
    assert config["n_envs"] == 32 and config["n_steps"] == 1
    rows = [np.loadtxt(run / f"{rank}.monitor.csv", delimiter=",", skiprows=2, ndmin=2) for rank in range(32)]
    assert [len(row) for row in rows] == [1] * 32


def test_enjoy_plays_the_goals_of_the_packages_evaluation(trained, tmp_path):
    zoo(
        "enjoy",
        "--algo",
        "genrl",
        "--env",
        ENV_ID,
        "-f",
        trained,
        "--no-render",
        "-n",
        12,
        "--seed",
        5,
        "--reward-log",
        tmp_path,
        "--device",
        "cpu",
    )
    played = np.loadtxt(tmp_path / "0.monitor.csv", delimiter=",", skiprows=2)[:, 0]
    model = GenRL.load(trained / RUN / "GenRL-Hockey-v0.zip", device="cpu")
    np.testing.assert_allclose(played, one_at_a_time(model, 12, seed=5), atol=1e-5)  # the Monitor keeps 6 digits


def test_record_video_writes_one_frame_per_episode(trained, tmp_path):
    zoo("record_video", "--algo", "genrl", "--env", ENV_ID, "-f", trained, "-n", 3, "-o", tmp_path)
    (video,) = tmp_path.glob("*.mp4")
    assert video.stat().st_size > 0


def test_the_zoo_and_train_policy_build_the_same_genrl_from_the_file(trained, hockey_generator, tmp_path, cli):
    from sb3_genrl.run.train import genrl_settings

    code, _, err = cli(
        "train-policy",
        "--task",
        "hockey",
        "--generator",
        hockey_generator,
        "--episodes",
        32,
        "--seed",
        3,
        "--device",
        "cpu",
        "--no-progress-bar",
        "--out",
        tmp_path / "run",
    )
    assert code == 0, err
    models = [
        GenRL.load(path, device="cpu")
        for path in (trained / RUN / "GenRL-Hockey-v0.zip", tmp_path / "run" / "genrl_policy.zip")
    ]
    # (the minibatch as GenRL fits it: train_policy passes the batch_size it caps, the zoo GenRL's default)
    names = [name for name in genrl_settings() if name not in ("policy_kwargs", "learning_rate", "batch_size")]
    zoo_run, package_run = (
        {name: getattr(model, name) for name in names}
        | {
            "minibatch_size": model.minibatch_size,
            "policy": type(model.policy),
            "policy_kwargs": model.policy_kwargs,
            "episodes_per_iteration": model.n_steps * model.n_envs,
            "learning_rate": model.lr_schedule(1.0),
        }
        for model in models
    )
    assert zoo_run == package_run
    assert [model.n_envs for model in models] == [32, 32]  # both play an iteration's episodes together by default
    entry = load_hyperparams("genrl", ENV_ID)
    assert zoo_run["hindsight_kwargs"] == entry["hindsight_kwargs"]
    assert zoo_run["episodes_per_iteration"] == entry["n_steps"]
    assert zoo_run["policy_kwargs"]["net_arch"] == entry["policy_kwargs"]["net_arch"]
    # the same seed, goals and settings: the same policy, to float rounding
    for zoo_tensor, package_tensor in zip(*(model.policy.state_dict().values() for model in models), strict=True):
        np.testing.assert_allclose(zoo_tensor.numpy(), package_tensor.numpy(), rtol=0, atol=1e-5)


@pytest.mark.slow  # about 15 s: two trials, each policy evaluated twice
@pytest.mark.filterwarnings("error:no generator found:UserWarning")  # enjoy finds the generator beside the copy
def test_a_small_study_tries_the_entry_first(hockey_generator, tmp_path):
    import optuna

    from sb3_genrl.zoo import held_out
    from sb3_genrl.zoo.sampler import SEARCH_SPACE, convert_genrl_params, entry_params

    storage = f"sqlite:///{tmp_path / 'study.db'}"
    zoo(
        "train",
        "--algo",
        "genrl",
        "--env",
        ENV_ID,
        "-optimize",
        "--n-trials",
        2,
        "--n-timesteps",
        16,
        "--eval-episodes",
        3,
        "--storage",
        storage,
        "--study-name",
        "tiny",
        "--seed",
        0,
        "-f",
        tmp_path / "logs",
        "--device",
        "cpu",
        "--no-optim-plots",
        "--optimization-log-path",
        tmp_path / "trials",
        *with_generator(hockey_generator),
    )
    trials = optuna.load_study(study_name="tiny", storage=storage).trials
    assert [trial.state for trial in trials] == [optuna.trial.TrialState.COMPLETE] * 2
    entry = load_hyperparams("genrl", ENV_ID)
    assert trials[0].params == entry_params(entry)
    first = convert_genrl_params(trials[0].params)
    assert first["n_steps"] == entry["n_steps"] and first["hindsight_kwargs"] == entry["hindsight_kwargs"]
    assert set(trials[1].params) == set(SEARCH_SPACE)
    assert all(value <= 0 for value in (trial.value for trial in trials))  # minus a distance to the goals
    # the entry's and the best trial's saved policies on held-out goals, by the package's evaluation
    assert (
        held_out.main(
            [
                "--env",
                ENV_ID,
                "--storage",
                storage,
                "--study-name",
                "tiny",
                "--trials",
                str(tmp_path / "trials"),
                "--goals",
                "4",
                "--out",
                str(tmp_path / "held_out.json"),
            ]
        )
        == 0
    )
    result = json.loads((tmp_path / "held_out.json").read_text())
    assert result["sb3_genrl"] and result["git_commit"]  # the version and the commit of the code that made it
    best = max(range(2), key=lambda number: trials[number].value)
    assert (result["entry"]["trial"], result["best"]["trial"]) == (0, best)
    for name in ("entry", "best"):
        model = GenRL.load(tmp_path / "trials" / f"trial_{result[name]['trial']}" / "best_model.zip", device="cpu")
        mean = -one_at_a_time(model, 4, EVAL_GOAL_SEED).mean()
        assert result[name]["enjoy_mean_m"] == pytest.approx(mean, abs=1e-5)  # rl-zoo3's enjoy on the same goals
        assert result[name]["held_out_mean_m"] == pytest.approx(mean, abs=0.05)  # batched: rounding, chaotic contacts
    assert result["better"] == min(("entry", "best"), key=lambda name: result[name]["held_out_mean_m"])


def test_evaluations_replay_the_tuning_goals(hockey_generator):
    from sb3_genrl.envs import get_task
    from stable_baselines3.common.env_util import make_vec_env

    from sb3_genrl.zoo.experiment import TuningGoals
    from sb3_genrl.zoo.wrapper import latent_action

    venv = TuningGoals(
        make_vec_env(ENV_ID, wrapper_class=latent_action, wrapper_kwargs={"generator": hockey_generator}, seed=0)
    )
    rng, task = np.random.default_rng(TUNING_GOAL_SEED), get_task("hockey").make_env()
    wanted = np.array([task.sample_goal(rng) for _ in range(3)], dtype=np.float32)
    for _ in range(2):  # each evaluation starts the same goals again
        goals = [venv.reset()[0]] + [venv.step(np.zeros((1, 2), np.float32))[0][0] for _ in range(2)]
        np.testing.assert_array_equal(np.array(goals), wanted)
    venv.close()


def test_a_missing_generator_names_the_command_that_makes_it(monkeypatch, tmp_path):
    import gymnasium as gym

    from sb3_genrl.zoo import latent_action

    monkeypatch.setenv("SB3_GENRL_CACHE", str(tmp_path))
    with pytest.raises(
        FileNotFoundError,
        match=r"generators/hockey/vae\.pt is not made yet: `python -m sb3_genrl\.zoo build-generator --env "
        r"GenRL/Hockey-v0` makes it \(as `python -m sb3_genrl\.zoo train --algo genrl --env GenRL/Hockey-v0` does",
    ):
        latent_action(gym.make(ENV_ID))
    with pytest.raises(FileNotFoundError, match="no generator file"):
        latent_action(gym.make(ENV_ID), generator=tmp_path / "none.pt")


def test_a_changed_generator_is_refused(hockey_generator):
    import gymnasium as gym

    from sb3_genrl.zoo import latent_action

    with pytest.raises(ValueError, match="is not the one this run was trained with"):
        latent_action(gym.make(ENV_ID), generator=hockey_generator, generator_sha256="0" * 64)


def test_the_cached_generator_is_the_quickstarts(quickstart_settings, tmp_path):
    from sb3_genrl.study.quickstart import DEMO_EPISODES, quickstart_demo_episodes
    from sb3_genrl.zoo import generators

    stage = quickstart_settings(tmp_path / "quick", task="hockey")["generator"]  # the quickstart's defaults
    # a package task's generator: the paper's checkpoint selection, its epochs as they are
    assert "selection" not in stage and "min_steps" not in stage
    recorded = generators.generator_settings("hockey")
    # the quickstart's recipe, at the generator stage's default count (hockey's quickstart alone makes fewer)
    assert quickstart_demo_episodes("basketball") == DEMO_EPISODES > quickstart_demo_episodes("hockey")
    assert (recorded["demo_episodes"], recorded["epochs"], recorded["preset"], recorded["eval_every"]) == (
        DEMO_EPISODES,
        stage["epochs"],
        stage["preset"],
        stage["eval_every"],
    )
    assert recorded["seed"] == generators.SEED == stage["seed"]


def test_a_demonstration_callback_gets_the_cached_generators_demonstrations(monkeypatch, tmp_path, hockey_generator):
    import shutil

    from gymnasium import spaces

    from sb3_genrl.data import write_dataset
    from sb3_genrl.data.fingerprints import dataset_fingerprint
    from sb3_genrl.genrl.demonstrations import DEMONSTRATION_CALLBACK, DemonstrationCallback
    from sb3_genrl.utils import atomic_write_json
    from sb3_genrl.zoo.experiment import WRAPPER, resolved_callback, resolved_wrapper
    from sb3_genrl.zoo.generators import default_demonstrations, default_generator, generator_settings

    monkeypatch.setenv("SB3_GENRL_CACHE", str(tmp_path))
    default_generator(ENV_ID).parent.mkdir(parents=True)
    shutil.copy(hockey_generator, default_generator(ENV_ID))  # the cached generator, made before
    atomic_write_json(default_generator(ENV_ID).parent / "stage.json", generator_settings(ENV_ID))
    wrapper = resolved_wrapper(WRAPPER, ENV_ID, "cpu")
    callback = [{DEMONSTRATION_CALLBACK: {"fit_steps": 10}}]
    with pytest.raises(
        FileNotFoundError,
        match=r"the cached generator's demonstrations .*generators/hockey/"
        r"demonstrations are missing",
    ):
        resolved_callback(callback, wrapper, ENV_ID)
    n, t = 3, 69
    arrays = {
        "observations": np.zeros((n, t + 1, 2), np.float32),
        "actions": np.zeros((n, t, 7), np.float32),
        "rewards": np.zeros((n, t)),
        "terminations": np.ones((n, t), bool),
        "truncations": np.zeros((n, t), bool),
        "reached": np.zeros((n, 2)),
        "sampled_goals": np.zeros((n, 2)),
    }
    dataset = write_dataset(
        default_demonstrations(ENV_ID),
        arrays,
        dataset_id="genrl/hockey-v0",
        genrl={"task": "hockey", "horizon": t},
        observation_space=spaces.Box(-1, 1, (2,), np.float32),
        action_space=spaces.Box(-0.5, 0.5, (7,), np.float32),
    )
    (resolved,) = resolved_callback(callback, wrapper, ENV_ID)
    assert resolved == {
        DEMONSTRATION_CALLBACK: {
            "fit_steps": 10,
            "dataset": str(dataset.resolve()),
            "dataset_fingerprint": dataset_fingerprint(dataset),
        }
    }
    assert DemonstrationCallback(**resolved[DEMONSTRATION_CALLBACK]).dataset == str(dataset.resolve())
    with pytest.raises(ValueError, match="are not the ones this run was trained with"):
        DemonstrationCallback(**resolved[DEMONSTRATION_CALLBACK] | {"dataset_fingerprint": "0" * 16})
    other = resolved_wrapper([{WRAPPER: {"generator": hockey_generator}}], ENV_ID, "cpu")
    with pytest.raises(ValueError, match="is not the cached one, whose demonstrations are known: give the generator's"):
        resolved_callback(callback, other, ENV_ID)
    given = [{DEMONSTRATION_CALLBACK: {"dataset": "D"}}]  # a callback that names its dataset keeps it
    assert resolved_callback(given, other, ENV_ID) == given


def test_every_task_entry_lies_in_the_search_space():
    from sb3_genrl.hyperparams import known_env_ids
    from sb3_genrl.zoo.sampler import convert_genrl_params, entry_params

    for env_id in ("GenRL/Hockey-v0", "GenRL/Basketball-v0"):
        assert env_id in known_env_ids("genrl")
        entry = load_hyperparams("genrl", env_id)
        converted = convert_genrl_params(entry_params(entry))
        entry["hindsight_kwargs"] = {"regression_steps": 0, **entry["hindsight_kwargs"]}  # hindsight's default
        assert {key: entry.get(key, converted[key]) for key in converted} == converted, env_id


def test_the_entry_point_names_its_scripts(capsys):
    assert main(["--help"]) == 0 and "{train,enjoy,record_video,build-generator}" in capsys.readouterr().out
    assert main(["plot_train"]) == 2 and "unknown script 'plot_train'" in capsys.readouterr().err
