"""The ``genrl`` command line: its grammar, its checks of every argument and path before any work, its one-line
errors, the commands not run elsewhere (play, baseline, compare), and the policy zips it refuses to unpickle."""

from __future__ import annotations

import base64
import csv
import json
import os
import pickle
import re
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import HANG_S

from sb3_genrl import GenRL, __version__
from sb3_genrl.checks import check_device, check_int, check_output_dir, check_output_file, check_seed
from sb3_genrl.cli import WORKFLOW
from sb3_genrl.curves import MONITOR_FILE, read_monitor


def _read_only_folder(tmp_path: Path) -> Path:
    """A folder nobody may write to: chmod 555, or for root (who ignores permissions) a read-only file system."""
    if os.geteuid() == 0:
        return Path("/sys")
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    return folder


def test_help_lists_the_commands_in_workflow_order_and_version(cli):
    code, printed, _ = cli("--help")
    assert code == 0 and "workflow order" in printed
    listed = re.findall(r"^    (\S+)", printed, flags=re.MULTILINE)
    assert tuple(listed) == WORKFLOW
    assert cli("--version")[:2] == (0, f"genrl {__version__}\n")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ("demos", "--task", "hockey", "--episodes", "-1", "--out", "D"),
            "argument --episodes: must be an integer between 1 and 100000000, got -1",
        ),
        (
            ("demos", "--task", "hockey", "--episodes", "2.5", "--out", "D"),
            "argument --episodes: expected an integer, got '2.5'",
        ),
        (("demos", "--task", "golf", "--out", "D"), "argument --task: unknown task 'golf'"),
        (("demos", "--task", "hockey", "--out", "FILE"), "argument --out: 'FILE' is a file; expected a folder"),
        (("demos", "--task", "hockey", "--out", "FILE/sub"), "argument --out: 'FILE/sub' cannot be created: 'FILE' is a file"),
        (("demos", "--task", "hockey", "--threads", "0", "--out", "D"), "argument --threads: must be an integer >= 1, got 0"),
        (
            ("quickstart", "--episodes", "-1", "--out", "D"),
            "argument --episodes: must be an integer between 1 and 100000000, got -1",
        ),
        (
            ("quickstart", "--demo-episodes", "0", "--out", "D"),
            "argument --demo-episodes: must be an integer between 4 and 100000000, got 0",
        ),
        (("quickstart", "--device", "bogus", "--out", "D"), "argument --device: must be 'auto' or a torch device"),
        (("quickstart", "--out", "FILE"), "argument --out: 'FILE' is a file; expected a folder"),
        (
            ("train-policy", "--task", "hockey", "--generator", "GEN", "--episodes", "8", "--seed", "-1", "--out", "D"),
            "argument --seed: must be an integer between 0 and 4294967295, got -1",
        ),
        (
            (
                "train-policy",
                "--task",
                "hockey",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--batch-episodes",
                "1",
                "--out",
                "D",
            ),
            "argument --batch-episodes: must be an integer >= 2, got 1",
        ),
        (
            ("train-policy", "--task", "hockey", "--generator", "missing.pt", "--episodes", "8", "--out", "D"),
            "argument --generator: 'missing.pt' does not exist",
        ),
        (
            (
                "train-policy",
                "--task",
                "hockey",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--genrl-kwargs",
                "[1]",
                "--out",
                "D",
            ),
            "argument --genrl-kwargs: expected a JSON object, got '[1]'",
        ),
        (
            ("train-policy", "--task", "hockey", "--generator", "GEN", "--episodes", "8", "--genrl-kwargs", "{", "--out", "D"),
            "argument --genrl-kwargs: not JSON",
        ),
        (
            (
                "train-policy",
                "--task",
                "hockey",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--genrl-kwargs",
                '{"hindsight_kwargs": {"history": -1}}',
                "--out",
                "D",
            ),
            "argument --e-step/--genrl-kwargs: hockey's entry in hyperparams/genrl.yml, --genrl-kwargs: "
            "hindsight_kwargs['history'] must be an integer >= 0, got -1",
        ),
        (
            (
                "train-policy",
                "--task",
                "hockey",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--genrl-kwargs",
                '{"hindsight_kwargs": {"regression_weighted": true}}',
                "--library-defaults",
                "--out",
                "D",
            ),
            "argument --e-step/--genrl-kwargs: GenRL's defaults, --genrl-kwargs: "
            "hindsight_kwargs['regression_weighted'] weights the regression's pulls, which needs regression_steps > 0",
        ),
        (
            (
                "train-policy",
                "--task",
                "hockey",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--genrl-kwargs",
                '{"gama": 1}',
                "--out",
                "D",
            ),
            "'gama' is not a GenRL setting",
        ),
        (
            (
                "train-policy",
                "--task",
                "basketball",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--e-step",
                "kl_penalty",
                "--out",
                "D",
            ),
            "argument --e-step/--genrl-kwargs: basketball's entry in hyperparams/genrl.yml, --e-step kl_penalty: "
            "hindsight_kwargs needs e_step='trpo'",
        ),
        (
            (
                "train-policy",
                "--task",
                "hockey",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--e-step",
                "kl_penalty",
                "--genrl-kwargs",
                '{"e_step": "trpo"}',
                "--out",
                "D",
            ),  # fmt: skip
            "--e-step kl_penalty and --genrl-kwargs' e_step 'trpo' disagree: give one of them",
        ),
        (
            ("baseline", "ppo", "--task", "hockey", "--demos", "D0", "--episodes", "8", "--bc-max-epochs", "-1", "--out", "D"),
            "argument --bc-max-epochs: must be an integer >= 1, got -1",
        ),
        (
            ("baseline", "ppo", "--task", "hockey", "--demos", "D0", "--episodes", "8", "--device", "cuda:7", "--out", "D"),
            "argument --device: ",
        ),
        (
            ("baseline", "ppo", "--task", "hockey", "--demos", "D0", "--episodes", "8", "--out", "FILE"),
            "argument --out: 'FILE' is a file",
        ),
        (("evaluate", "GEN", "--data", "D0", "--n", "0", "--out", "D"), "argument --n: must be an integer >= 1, got 0"),
        (("evaluate", "GEN", "--data", "D0", "--out", "FILE"), "argument --out: 'FILE' is a file"),
        (("evaluate", "GEN", "--data", "D0", "--rank-by", "fid", "--out", "D"), "argument --rank-by: invalid choice: 'fid'"),
        (
            ("evaluate", "GEN", "--data", "D0", "--min-precision", "1.5", "--out", "D"),
            "argument --min-precision: must be a number in [0, 1], got 1.5",
        ),
        (("compare", "--runs", "D0", "--out", "FILE"), "argument --out: 'FILE' is a file"),
        (("study", "--workers", "0", "--out", "D"), "argument --workers: must be an integer >= 1, got 0"),
        (("study", "--models", "VAE10", "--out", "D"), "argument --models: invalid choice: 'VAE10'"),
        (("study", "--out", "FILE"), "argument --out: 'FILE' is a file"),
        (("play", "--out", "FILE"), "argument --out: 'FILE' is a file"),
        (("video", "--task", "hockey", "--generator", "GEN", "--out", "v.avi"), "argument --out: 'v.avi' must end in .mp4"),
        (("video", "--task", "hockey", "--generator", "GEN", "--out", "D0"), "argument --out: 'D0' is a folder"),
        (("video", "--task", "hockey", "--generator", "GEN", "--goals", "0", "--out", "v.gif"), "argument --goals"),
        (("train-generator", "--data", "D0", "--batch-size", "0", "--out", "g.pt"), "argument --batch-size: must be"),
        (("train-generator", "--data", "", "--out", "g.pt"), "argument --data: is empty; expected a path"),
    ],
)
def test_arguments_and_paths_are_checked_before_any_work(tmp_path, monkeypatch, cli, argv, message):
    monkeypatch.chdir(tmp_path)
    Path("FILE").write_text("")
    Path("GEN").write_text("")
    Path("D0").mkdir()
    code, printed, err = cli(*argv)
    assert code == 2 and message in err and printed == ""
    assert err.splitlines()[-1].startswith(f"genrl {argv[0]}: error: argument ")  # argparse's one line, no traceback
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D0", "FILE", "GEN"]  # nothing was written


def test_ranking_by_the_prior_rollout_without_a_task_is_refused_before_any_work(tmp_path, monkeypatch, cli):
    monkeypatch.chdir(tmp_path)
    Path("GEN").write_text("")
    Path("D0").mkdir()
    code, printed, err = cli("evaluate", "GEN", "--data", "D0", "--rank-by", "prior_median", "--out", "D")
    assert code == 2 and printed == ""
    assert err.strip() == "genrl evaluate: error: rank_by='prior_median' needs a task: the prior rollout runs only with one"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D0", "GEN"]


def test_an_mp4_without_imageio_ffmpeg_is_refused_before_rendering(tmp_path, monkeypatch, cli):
    import sys

    monkeypatch.chdir(tmp_path)
    Path("GEN").write_text("")
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # what an environment without the package gives
    code, printed, err = cli("video", "--task", "hockey", "--generator", "GEN", "--out", "v.mp4")
    assert code == 2 and printed == "" and "writing 'v.mp4' needs imageio-ffmpeg" in err and "or write a .gif" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["GEN"]


@pytest.mark.parametrize("command", ["play", "quickstart", "study", "evaluate --data . GEN", "compare --runs ."])
def test_an_output_folder_that_cannot_be_written_is_refused(tmp_path, monkeypatch, cli, command):
    monkeypatch.chdir(tmp_path)
    Path("GEN").write_text("")
    out = _read_only_folder(tmp_path) / "out"
    code, _, err = cli(*command.split(), "--out", out)
    assert code == 2 and f"argument --out: '{out}' cannot be written" in err and not out.exists()


@pytest.mark.parametrize(
    "error", [ValueError, FileNotFoundError, PermissionError, FileExistsError, IsADirectoryError, NotADirectoryError]
)
def test_known_errors_are_one_line_with_exit_status_2(tmp_path, monkeypatch, cli, error):
    from sb3_genrl.cli import commands

    def fail(*args, **kwargs):
        raise error("what went wrong, and where")

    monkeypatch.setattr(commands, "play_scripted", fail)  # the library function the command calls
    assert cli("play", "--out", tmp_path) == (2, "", "genrl play: error: what went wrong, and where\n")


def test_the_checks_name_the_argument_and_what_was_expected(tmp_path):
    for value in (2.5, "2", True, None):
        with pytest.raises(ValueError, match=rf"n_threads must be an integer >= 1, got {re.escape(repr(value))} \("):
            check_int(value, "n_threads")
    assert check_int(np.int64(3), "n") == 3 and type(check_int(np.int64(3), "n")) is int
    with pytest.raises(ValueError, match="seed must be an integer between 0 and 4294967295, got 4294967296"):
        check_seed(2**32)
    assert check_device("cpu") == "cpu" and check_device("auto") == "auto"
    for device in ("bogus", "cuda:99", "tpu"):
        with pytest.raises(ValueError, match="device"):
            check_device(device)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    with pytest.raises(ValueError, match="out_dir '.*full' already exists and is not empty"):
        check_output_dir(tmp_path / "full", empty=True)
    assert check_output_dir(tmp_path / "new" / "deeper") == tmp_path / "new" / "deeper"
    assert not (tmp_path / "new").exists()  # checked, not created
    with pytest.raises(ValueError, match="cannot be written"):
        check_output_file(_read_only_folder(tmp_path) / "model.pt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full"] + (["read-only"] if os.geteuid() else [])


def test_library_functions_check_before_any_work(tmp_path):
    from sb3_genrl.envs.demonstrations import make_demonstrations

    from sb3_genrl.study.quickstart import quickstart

    for threads in (2.5, "2", 0):
        with pytest.raises(ValueError, match="n_threads must be an integer >= 1"):
            make_demonstrations("hockey", 4, tmp_path / "demos", n_threads=threads, progress_bar=False)
    with pytest.raises(ValueError, match="policy_episodes must be an integer between 1 and 100000000, got -1"):
        quickstart(tmp_path / "quick", task="hockey", policy_episodes=-1)
    with pytest.raises(ValueError, match="device"):
        quickstart(tmp_path / "quick", task="hockey", device="bogus")
    from sb3_genrl.run import train_policy

    with pytest.raises(ValueError, match="hindsight_kwargs needs e_step='trpo'"):  # GenRL's settings, before its Monitor
        train_policy("hockey", "missing.pt", episodes=8, out_dir=tmp_path / "policy", e_step="kl_penalty", hindsight_kwargs={})
    with pytest.raises(ValueError, match="n_steps=16: give the episodes per iteration as batch_episodes"):
        train_policy("hockey", "missing.pt", episodes=8, out_dir=tmp_path / "policy", n_steps=16)
    assert list(tmp_path.iterdir()) == []  # no demonstrations were made, no folder created


def test_every_library_entry_point_checks_its_output_path_and_seed_first(tmp_path, hockey_generator):
    from sb3_genrl.baselines.compare import compare_runs
    from sb3_genrl.baselines.train import train_baseline
    from sb3_genrl.envs.demonstrations import make_demonstrations

    from sb3_genrl.generative import train_generator
    from sb3_genrl.metrics import evaluate_generators
    from sb3_genrl.run import train_policy
    from sb3_genrl.showcase import play_scripted
    from sb3_genrl.study import run_study
    from sb3_genrl.study.quickstart import quickstart
    from sb3_genrl.video import record_video

    trajectories = np.zeros((5, 69, 7), dtype=np.float32)
    entry_points = {
        "make_demonstrations": lambda out, seed: make_demonstrations("hockey", 2, out, seed=seed, progress_bar=False),
        "train_generator": lambda out, seed: train_generator(trajectories, out=out / "g.pt", seed=seed),
        "evaluate_generators": lambda out, seed: evaluate_generators(
            [hockey_generator], trajectories, n=5, out_dir=out, seed=seed
        ),
        "train_policy": lambda out, seed: train_policy("hockey", hockey_generator, episodes=8, out_dir=out, seed=seed),
        "train_baseline": lambda out, seed: train_baseline(
            "latent-ppo", "hockey", episodes=8, out_dir=out, seed=seed, generator=hockey_generator
        ),
        "compare_runs": lambda out, seed: compare_runs([tmp_path], out),
        "play_scripted": lambda out, seed: play_scripted(out, seed=seed),
        "record_video": lambda out, seed: record_video("hockey", out / "v.gif", generator=hockey_generator, seed=seed),
        "quickstart": lambda out, seed: quickstart(out, task="hockey", seed=seed),
        "run_study": lambda out, seed: run_study("hockey", "smoke", out),
    }
    (tmp_path / "file").write_text("")
    for name, call in entry_points.items():
        with pytest.raises(ValueError, match="is a file"):
            call(tmp_path / "file", 0)
        if name not in ("compare_runs", "run_study"):  # these two draw nothing at random
            with pytest.raises(ValueError, match="seed must be an integer between 0 and 4294967295, got -1"):
                call(tmp_path / "out", -1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # nothing was written


def test_play_renders_the_scripted_motion_it_reports(tmp_path, cli):
    code, printed, err = cli("play", "--task", "hockey", "--seed", 3, "--out", tmp_path)
    assert code == 0, err
    assert printed == f"wrote {tmp_path / 'report.md'}\n"
    assert (tmp_path / "hockey.gif").stat().st_size > 1000 and (tmp_path / "hockey_strip.png").stat().st_size > 1000
    report = (tmp_path / "report.md").read_text()
    assert "## hockey" in report and "## basketball" not in report
    # Replayed here step by step: the scripted hit of seed 3 reaches the point the report gives.
    from sb3_genrl.envs import get_task

    spec = get_task("hockey")
    env = gym.make(spec.env_id).unwrapped
    env.reset(options={"goal": (spec.goal_low + spec.goal_high) / 2})
    for action in spec.sample_expert(np.random.default_rng(3)):
        _, _, terminated, _, info = env.step(action)
    assert terminated and f"reached: ({info['reached'][0]:.2f}, {info['reached'][1]:.2f}) m" in report
    assert f"table contacts: {info['table_contacts']}" in report


@pytest.fixture(scope="module")
def runs(tmp_path_factory, hockey_generator):
    """A GenRL run (hockey's settings with --genrl-kwargs laid over them: relabelled pulls kept for two iterations, the
    mean fitted to them by 3 weighted steps per iteration) and a latent-space PPO run on hockey, both through the
    command line."""
    from sb3_genrl.cli import main

    root = tmp_path_factory.mktemp("runs")
    assert (
        main(
            [
                "train-policy",
                "--task",
                "hockey",
                "--generator",
                hockey_generator,
                "--episodes",
                "32",
                "--batch-episodes",
                "16",
                "--genrl-kwargs",
                '{"hindsight_kwargs": {"history": 2, "regression_steps": 3, "regression_weighted": true}}',
                "--device",
                "cpu",
                "--no-progress-bar",
                "--out",
                str(root / "genrl"),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "baseline",
                "latent-ppo",
                "--task",
                "hockey",
                "--generator",
                hockey_generator,
                "--episodes",
                "16",
                "--algorithm-kwargs",
                '{"gamma": 0.9}',
                "--device",
                "cpu",
                "--no-progress-bar",
                "--out",
                str(root / "ppo"),
            ]
        )
        == 0
    )
    return root


def test_baseline_and_compare(runs, tmp_path, cli, hockey_generator):
    summary = json.loads((runs / "ppo" / "summary.json").read_text())
    episodes = read_monitor(runs / "ppo" / MONITOR_FILE)
    assert summary["episodes_played"] == len(episodes["return"]) == 64  # one PPO rollout of 64 one-step episodes
    assert summary["max_reward"] == pytest.approx(episodes["return"].max())
    # The final evaluation of a latent-space baseline: its deterministic latent action for each held-out goal,
    # played through the latent-action env one goal at a time; GenRL's through evaluate_on_goals.
    from sb3_genrl.baselines.evaluation import evaluate_trained, load_trained
    from sb3_genrl.baselines.feedback import held_out_goals

    from sb3_genrl import LatentActionWrapper
    from sb3_genrl.generative import load
    from sb3_genrl.hyperparams import EVAL_GOAL_SEED
    from sb3_genrl.run import evaluate_on_goals

    generator = load(hockey_generator)
    latent_ppo = load_trained("latent-ppo", runs / "ppo" / "latent-ppo_policy.zip", "hockey")
    # the entry's 64 steps per update played as 64 envs of one step, together
    assert latent_ppo.gamma == 0.9 and summary["settings"] == {"n_steps": 1, "batch_size": 64, "gamma": 0.9}
    assert summary["n_envs"] == latent_ppo.n_envs == 64
    env = LatentActionWrapper(gym.make("GenRL/Hockey-v0"), generator)
    rewards = []
    for goal in held_out_goals("hockey", 100, EVAL_GOAL_SEED):
        obs, _ = env.reset(options={"goal": goal})
        rewards.append(env.step(latent_ppo.predict(obs, deterministic=True)[0])[1])
    assert summary["final_eval"]["mean_distance"] == pytest.approx(-np.mean(rewards), rel=1e-5)
    genrl = load_trained("genrl", runs / "genrl" / "genrl_policy.zip", "hockey", generator=generator)
    settings = json.loads((runs / "genrl" / "summary.json").read_text())["genrl_settings"]
    # the task's entry with --genrl-kwargs merged into its hindsight_kwargs, as the model was built
    assert (
        settings["hindsight_kwargs"]
        == genrl.hindsight_kwargs
        == {"history": 2, "regression_steps": 3, "regression_weighted": True}
    )
    assert (genrl.hindsight.history, genrl.hindsight.regression_steps, genrl.hindsight.regression_weighted) == (2, 3, True)
    assert settings["policy_kwargs"] == {"net_arch": {"pi": [64, 64, 64], "vf": [64, 64]}}
    _, genrl_rewards, _ = evaluate_on_goals(genrl, "hockey", goals=100, seed=EVAL_GOAL_SEED)
    final = evaluate_trained("genrl", genrl, "hockey", generator=generator)
    assert final["mean_distance"] == pytest.approx(-genrl_rewards.mean(), rel=1e-6)
    assert final["median_distance"] == pytest.approx(np.median(-genrl_rewards), rel=1e-6)

    code, printed, err = cli("compare", "--task", "hockey", "--runs", runs / "genrl", runs / "ppo", "--out", tmp_path)
    assert code == 0, err
    with open(tmp_path / "comparison.csv", newline="") as file:
        rows = {row["method"]: row for row in csv.DictReader(file)}
    assert sorted(rows) == ["GenRL", "PPO on latent"]
    curves = {}
    for method, folder in (("GenRL", "genrl"), ("PPO on latent", "ppo")):
        with open(runs / folder / "learning_curve.csv", newline="") as file:
            curves[method] = [(float(r["episodes"]), float(r["mean_reward"])) for r in csv.DictReader(file)]
    budget = 32  # the end of the shorter run: GenRL's 32 episodes
    for method, curve in curves.items():
        x, y = np.array(curve).T
        row = rows[method]
        assert int(row["budget"]) == budget and float(row["final_mean_reward"]) == pytest.approx(y[-1])
        assert float(row["reward_at_budget"]) == pytest.approx(np.interp(budget, x, y))
        contacts = read_monitor(runs / ("genrl" if method == "GenRL" else "ppo") / MONITOR_FILE)["table_contacts"]
        assert float(row["table_contacts_per_episode"]) == pytest.approx(contacts.mean())
    assert "| GenRL | 1 |" in printed and (tmp_path / "reward_vs_episodes.png").stat().st_size > 1000

    code, _, err = cli("compare", "--runs", tmp_path, "--out", tmp_path / "again")
    assert code == 2 and "is not a run folder (no summary.json)" in err
    code, _, err = cli("baseline", "ppo", "--task", "hockey", "--episodes", 8, "--out", tmp_path / "ppo")
    assert code == 2 and "genrl baseline: error: ppo needs demonstrations" in err and not (tmp_path / "ppo").exists()


def test_baseline_offers_every_baseline_and_checks_its_inputs_first(cli, tmp_path):
    from sb3_genrl.baselines import BASELINES, LATENT_BASELINES

    for algorithm in BASELINES:  # each one is a choice, and refused without its inputs before any work
        code, printed, err = cli("baseline", algorithm, "--task", "hockey", "--episodes", 8, "--out", tmp_path / algorithm)
        needs = "a generator" if algorithm in LATENT_BASELINES else "demonstrations"
        assert code == 2 and f"genrl baseline: error: {algorithm} needs {needs}" in err and printed == "", err
        assert not (tmp_path / algorithm).exists()
    code, _, err = cli(
        "baseline",
        "latent-sac",
        "--task",
        "hockey",
        "--generator",
        tmp_path,
        "--episodes",
        8,
        "--algorithm-kwargs",
        '{"gama": 1}',
        "--out",
        tmp_path / "sac",
    )
    assert code == 2 and "latent-sac (SAC) has no setting 'gama'" in err and not (tmp_path / "sac").exists()
    code, _, err = cli(
        "baseline", "latent-sac", "--task", "hockey", "--episodes", 8, "--algorithm-kwargs", "[1]", "--out", tmp_path / "sac"
    )
    assert code == 2 and "expected a JSON object" in err


class _Payload:
    """Unpickling this runs code: it writes ``marker``."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return exec, (f"open({self.marker!r}, 'w').write('ran')",)


def _with_payload(policy_zip: Path, out: Path, key: str, marker: Path) -> Path:
    """A copy of ``policy_zip`` whose ``data`` entry ``key`` is a pickle that writes ``marker`` when loaded."""
    with zipfile.ZipFile(policy_zip) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(entries["data"])
    readable = {k: v for k, v in data.get(key, {}).items() if k != ":serialized:"} if key in data else {}
    data[key] = {**readable, ":serialized:": base64.b64encode(pickle.dumps(_Payload(marker))).decode()}
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(out, "w") as archive:
        for name, content in entries.items():
            archive.writestr(name, content)
    return out


def test_policy_zips_are_loaded_without_unpickling(runs, tmp_path, cli):
    from sb3_genrl import GenRL
    from sb3_genrl.run.loading import load_policy

    policy = runs / "genrl" / "genrl_policy.zip"
    marker = tmp_path / "marker"
    goals = np.array([[1.0, 0.1], [0.8, -0.3]], dtype=np.float32)
    expected = GenRL.load(policy, device="cpu").predict(goals, deterministic=True)[0]
    # Payloads in the entries SB3 would unpickle: the safe loader rebuilds them and never unpickles the file's.
    for key in ("observation_space", "ep_info_buffer", "lr_schedule"):
        evil = _with_payload(policy, tmp_path / f"{key}.zip", key, marker)
        model = load_policy(evil, gym.make("GenRL/Hockey-v0"))  # the generator: the file the zip names
        np.testing.assert_array_equal(model.predict(goals, deterministic=True)[0], expected)
        assert not marker.exists(), key
    # The policy class is read from its pickle's opcodes, never run: anything but a reference to an allowed class
    # (here a payload, with the readable description of SB3's class beside it) is refused.
    evil = _with_payload(policy, tmp_path / "policy_class.zip", "policy_class", marker)
    with pytest.raises(ValueError, match="policy class \\(not a plain class reference\\) that cannot be loaded"):
        load_policy(evil, gym.make("GenRL/Hockey-v0"))
    assert not marker.exists()
    # An entry it cannot rebuild is refused, through the command line too, unless the user trusts the file.
    evil = _with_payload(policy, tmp_path / "extra.zip", "backdoor", marker)
    code, _, err = cli("video", "--task", "hockey", "--policy", evil, "--goals", 1, "--out", tmp_path / "v.gif")
    assert code == 2 and "pickled 'backdoor'" in err and "--trust-policy" in err
    assert not marker.exists() and not (tmp_path / "v.gif").exists()
    load_policy(evil, gym.make("GenRL/Hockey-v0"), trust=True)  # what SB3's own load does: the payload runs
    assert marker.read_text() == "ran"


def test_sub_seeds_keep_the_sums_in_range_and_stay_in_range_past_32_bits():
    from sb3_genrl.checks import MAX_SEED, sub_seed

    assert sub_seed(5, 1) == 6 and sub_seed(0, 640) == 640 and sub_seed(MAX_SEED - 3, 3) == MAX_SEED
    past = [sub_seed(MAX_SEED, key) for key in (1, 2, 640)]
    assert all(0 <= seed <= MAX_SEED for seed in past) and len(set(past)) == 3
    assert past[0] == int(np.random.SeedSequence(MAX_SEED, spawn_key=(1,)).generate_state(1)[0])


def test_every_command_runs_torch_on_one_thread(tmp_path, monkeypatch, cli):
    import torch

    from sb3_genrl.cli import commands

    seen = []
    monkeypatch.setattr(commands, "compare_command", lambda args: seen.append(torch.get_num_threads()) or 0)
    torch.set_num_threads(2)  # what torch picks on a 2-core machine
    assert cli("compare", "--runs", tmp_path, "--out", tmp_path / "out")[0] == 0 and seen == [1]


def test_absurd_counts_and_too_few_demonstrations_are_refused_before_any_work(tmp_path, cli, hockey_generator):
    from sb3_genrl.study.quickstart import quickstart

    huge = str(10**12)
    for argv in (
        ["train-policy", "--task", "hockey", "--generator", hockey_generator, "--episodes", huge],
        ["demos", "--task", "hockey", "--episodes", huge],
        ["baseline", "latent-trpo", "--task", "hockey", "--generator", hockey_generator, "--episodes", huge],
    ):
        code, _, err = cli(*argv, "--out", tmp_path / "run")
        assert code == 2 and "--episodes: must be an integer between 1 and 100000000" in err
    code, _, err = cli(
        "video", "--task", "hockey", "--generator", hockey_generator, "--goals", huge, "--out", tmp_path / "v.gif"
    )
    assert code == 2 and "--goals: must be an integer between 1 and 100" in err
    code, _, err = cli("quickstart", "--demo-episodes", 1, "--out", tmp_path / "quick")
    assert code == 2 and "--demo-episodes: must be an integer between 4 and" in err
    with pytest.raises(ValueError, match="demo_episodes must be an integer between 4 and"):
        quickstart(tmp_path / "quick", task="hockey", demo_episodes=3)
    assert not (tmp_path / "run").exists() and not (tmp_path / "quick").exists()


def test_a_full_disk_and_an_interrupt_are_one_line_with_their_exit_status(tmp_path, monkeypatch, cli):
    import errno

    from sb3_genrl.cli import commands

    def fails_with(error):
        def command(args):
            raise error

        return command

    for error, status, line in (
        (
            OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "x.csv")),
            1,
            f"error: No space left on device: '{tmp_path / 'x.csv'}'",
        ),
        (KeyboardInterrupt(), 130, "interrupted; rerun the same command to resume"),
        (
            RuntimeError("[enforce fail at inline_container.cc:664] . unexpected pos 64 vs 0"),
            1,
            "error: torch could not write a file (is the disk full?): [enforce fail at inline_container.cc:664]",
        ),
    ):
        monkeypatch.setattr(commands, "compare_command", fails_with(error))
        code, _, err = cli("compare", "--runs", tmp_path, "--out", tmp_path / "out")
        assert code == status and err.startswith(f"genrl compare: {line}") and err.count("\n") == 1


def test_a_full_disk_in_a_file_that_grows_as_the_run_goes_names_the_output(tmp_path, monkeypatch, cli):
    """The Monitor file, the training log and TensorBoard's events are written as the run goes, not atomically: a full
    disk there says only "No space left on device", and the command names its output."""
    import errno

    from sb3_genrl.cli import commands

    def disk_full(args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(commands, "compare_command", disk_full)
    code, _, err = cli("compare", "--runs", tmp_path, "--out", tmp_path / "out")
    assert code == 1 and err == f"genrl compare: error: No space left on device: writing '{tmp_path / 'out'}'\n"


def test_ctrl_c_of_a_run_with_env_processes_exits_130_in_one_line(tmp_path, hockey_generator):
    import signal
    import subprocess
    import sys
    import time

    run = tmp_path / "run"
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sb3_genrl.cli",
            "train-policy",
            "--task",
            "hockey",
            "--generator",
            hockey_generator,
            "--episodes",
            "100000",
            "--batch-episodes",
            "2",
            "--n-envs",
            "2",
            "--out",
            str(run),
            "--no-progress-bar",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        # Ctrl-C's disposition in a terminal: a suite started in the background of a script inherits SIGINT ignored
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    monitor = run / "episodes.monitor.csv"
    try:
        # The run is training once its Monitor file has rows, however long a loaded machine takes to get there.
        while not (monitor.is_file() and len(monitor.read_text().splitlines()) > 6):
            assert process.poll() is None, process.communicate()[1]
            time.sleep(0.2)
        os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C does: the whole process group
        _, err = process.communicate(timeout=HANG_S)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130 and "Traceback" not in err
    assert err.strip().splitlines()[-1] == "genrl train-policy: interrupted; rerun the same command to resume"


def test_wrong_types_in_genrl_kwargs_are_refused_before_the_run_folder_is_claimed(tmp_path, cli, hockey_generator):
    """A string for a number, a float for an integer, ``net_arch: "big"``, a KL bound of 0: one line, exit status 2,
    and the run folder not claimed, so the corrected command runs without --overwrite (the wrong types used to fail
    with a traceback after run_record.json was written)."""
    run = tmp_path / "run"
    argv = (
        "train-policy",
        "--task",
        "hockey",
        "--generator",
        hockey_generator,
        "--episodes",
        8,
        "--batch-episodes",
        8,
        "--library-defaults",
        "--device",
        "cpu",
        "--no-progress-bar",
        "--out",
        run,
    )
    for genrl_kwargs, message in (
        ('{"target_kl": "0.01"}', "target_kl must be a finite number > 0 (the E-step's KL bound), got '0.01' (str)"),
        ('{"n_critic_updates": 2.5}', "n_critic_updates must be a positive integer, got 2.5"),
        ('{"policy_kwargs": {"net_arch": "big"}}', "policy_kwargs['net_arch'] must be a list of positive layer sizes"),
        ('{"target_kl": 0}', "target_kl must be a finite number > 0 (the E-step's KL bound), got 0"),
        ('{"latent_clip": -1.0}', "latent_clip must be a finite number > 0, got -1.0"),
    ):
        code, printed, err = cli(*argv, "--genrl-kwargs", genrl_kwargs)
        assert code == 2 and printed == "" and message in err and err.count("\n") == 1, err
        assert err.startswith("genrl train-policy: error: argument --e-step/--genrl-kwargs: GenRL's defaults")
        assert not (run / "run_record.json").exists()
    code, printed, err = cli(*argv, "--genrl-kwargs", '{"target_kl": 0.02, "latent_clip": 1.0}')
    assert code == 0 and "GenRL on hockey: 8 episodes" in printed
    assert GenRL.load(run / "genrl_policy.zip", device="cpu").action_space.high.tolist() == [1.0, 1.0]


def test_options_that_would_set_nothing_are_refused_before_any_work(tmp_path, monkeypatch, cli):
    """An option that the rest of the command leaves unused (a cluster address without the Ray executor, the prior
    rollout's options without a task, a generator for a baseline that acts in action space) is refused, not ignored."""
    monkeypatch.chdir(tmp_path)
    Path("GEN").write_text("")
    Path("D0").mkdir()
    for argv, message in (
        (
            ("study", "--scale", "smoke", "--address", "localhost:1", "--out", "D"),
            "address 'localhost:1' is a Ray cluster's, which needs executor='ray' (--executor ray)",
        ),
        (
            ("evaluate", "GEN", "--data", "D0", "--contexts", "8", "--prior-seed", "3", "--out", "D"),
            "--contexts, --prior-seed set the prior rollout, which runs only with --task",
        ),
        (
            ("baseline", "ppo", "--task", "hockey", "--demos", "D0", "--generator", "GEN", "--episodes", "8", "--out", "D"),
            "ppo acts in action space and takes no generator",
        ),
        (
            (
                "baseline",
                "latent-ppo",
                "--task",
                "hockey",
                "--generator",
                "GEN",
                "--episodes",
                "8",
                "--checkpoint-every",
                "32",
                "--out",
                "D",
            ),
            "argument --checkpoint-every: latent-ppo is not checkpointed (only sac, sac-no-prefill, sac-her)",
        ),  # fmt: skip
    ):
        code, printed, err = cli(*argv)
        assert code == 2 and printed == "" and message in err, (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D0", "GEN"]
