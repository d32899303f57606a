"""The study (smoke scale through ``genrl study``, the Ray executor), the quickstart and the video command."""

import contextlib
import csv
import json
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest
from conftest import HANG_S, policy_distances
from sb3_genrl.envs import get_task

from sb3_genrl.hyperparams import EVAL_GOAL_SEED, load_genrl_settings
from sb3_genrl.run.stages import SettingsConflictError
from sb3_genrl.run.train import genrl_settings
from sb3_genrl.study import run_study
from sb3_genrl.study.scales import SCALES, task_scale

SMOKE_MODELS = ("VAE1", "GAN1")  # one of each kind: every table and plot of the study has something to show


def _csv_rows(path):
    with open(path, newline="") as file:
        return list(csv.DictReader(file))


@pytest.mark.slow
def test_smoke_study_writes_every_table_and_plot_and_resumes(tmp_path, cli, monkeypatch):
    code, out, err = cli(
        "study",
        "--task",
        "hockey",
        "--scale",
        "smoke",
        "--models",
        *SMOKE_MODELS,
        "--workers",
        "1",
        "--device",
        "cpu",
        "--out",
        tmp_path,
    )
    root = tmp_path / "hockey"
    assert code == 0, err
    assert f"wrote {root / 'report.md'}" in out
    rows = {row["model"]: row for row in json.loads((root / "results.json").read_text())}
    assert sorted(rows) == sorted(SMOKE_MODELS)
    for name, row in rows.items():
        # Each model's row holds its own evaluation file's measures and its policies' best rewards.
        evaluation = json.loads((root / "evaluation" / f"{name}.json").read_text())
        assert all(row[m] == evaluation[m] for m in ("precision", "recall", "delta_1", "delta_2", "mean_delta"))
        summaries = [
            json.loads((root / "policies" / name / f"seed{s}" / "summary.json").read_text())
            for s in range(SCALES["smoke"].seeds)
        ]
        assert row["rewards"] == [s["best_mean_reward"] for s in summaries] and row["score"] == max(row["rewards"])
        assert row["final"] == np.mean([s["final_mean_reward"] for s in summaries]) and row["half_score"] <= row["score"]
        assert [epoch for epoch, _ in row["selection"]] == [1, 2] and row["prior_median"] == evaluation["prior_median"]
        assert all(s["genrl_settings"]["n_steps"] == load_genrl_settings("GenRL/Hockey-v0")[1] for s in summaries)
        assert all(seconds > 0 for seconds in row["cpu_seconds"].values()), row["cpu_seconds"]
        # the policies' record holds the GenRL settings the runs played
        assert json.loads((root / "policies" / "stage.json").read_text())["genrl"] == summaries[0]["genrl_settings"]
        assert all(s["episodes"] == SCALES["smoke"].policy_episodes for s in summaries)
    table1 = {row["model"]: row for row in _csv_rows(root / "tables" / "table1_models.csv")}
    assert {name: float(row["best reward"]) for name, row in table1.items()} == {n: r["score"] for n, r in rows.items()}
    measures = {row["model"]: row for row in _csv_rows(root / "tables" / "measures.csv")}
    assert all(float(measures[n]["recall"]) == rows[n]["recall"] for n in rows)
    for name in ("table1_models", "measures", "correlation"):
        assert (root / "tables" / f"{name}.md").read_text().startswith("| ")
    for name in ("learning_curves_vae", "learning_curves_gan", "precision_recall", "disentanglement", "recall_vs_reward"):
        assert (root / "plots" / f"{name}.png").stat().st_size > 1000
    # The comparison: GenRL with the best generator and each baseline, one seed each, their curves and table contacts.
    comparison = _csv_rows(root / "comparison" / "comparison.csv")
    assert [row["method"] for row in comparison] == [
        "GenRL",
        "PPO (BC)",
        "SAC (prefilled)",
        "SAC (no prefill)",
        "SAC + HER",
        "PPO on latent",
        "SAC on latent",
        "TRPO on latent",
    ]
    assert all(row["seeds"] == "1" for row in comparison)
    for name in ("reward_vs_episodes.png", "table_contacts.png"):
        assert (root / "comparison" / name).stat().st_size > 1000
    best = max(rows.values(), key=lambda r: r["score"])
    report = (root / "report.md").read_text()
    assert f"Best generator: **{best['model']}** (best reward {best['score']:.3f}" in report
    for section in (
        "Table 1",
        "The ranking's stability",
        "Tables 4-5",
        "Tables 2-3",
        "Generator training",
        "GenRL vs PPO vs SAC",
    ):
        assert f"## {section}" in report

    # The report states the settings the stages recorded.
    smoke = SCALES["smoke"]
    assert f'"demo_episodes": {smoke.demo_episodes}, "generator_epochs": {smoke.generator_epochs},' in report

    # A rerun finds every result and recomputes nothing: the files are left as they were.
    outputs = [
        *root.glob("policies/*/seed*/summary.json"),
        *root.glob("generators/*.pt"),
        *root.glob("evaluation/*.json"),
        *root.glob("comparison/*/summary.json"),
        root / "demonstrations",
    ]
    stamps = {p: p.stat().st_mtime_ns for p in outputs}
    correlation = (root / "tables" / "correlation.csv").read_text()
    # ... and the jobs finishing in another order (as they do with workers) leaves the rows and intervals as they were
    from sb3_genrl.study import runner

    def reversed_map(workers):
        def run(jobs):
            yield from reversed([fn(*args) for fn, args in jobs])

        return run

    monkeypatch.setattr(runner, "_local_map", reversed_map)
    run_study("hockey", "smoke", tmp_path, workers=1, models=SMOKE_MODELS)
    assert stamps == {p: p.stat().st_mtime_ns for p in outputs}
    assert [row["model"] for row in json.loads((root / "results.json").read_text())] == list(SMOKE_MODELS)
    assert (root / "tables" / "correlation.csv").read_text() == correlation

    # Another scale into the same folder is refused before any work, naming the folders and settings that differ.
    with pytest.raises(SettingsConflictError) as error:
        run_study("hockey", "small", tmp_path, workers=1, models=SMOKE_MODELS)
    message, small = str(error.value), SCALES["small"]
    assert f"{root / 'demonstrations'}: episodes {smoke.demo_episodes} (recorded) vs {small.demo_episodes}" in message
    assert f"{root / 'generators'}: epochs {smoke.generator_epochs} (recorded) vs {small.generator_epochs}" in message
    small_hockey = task_scale(small.as_dict(), "hockey")
    assert f"{root / 'policies'}: episodes {smoke.policy_episodes} (recorded) vs {small_hockey['policy_episodes']}" in message
    assert json.loads((tmp_path / "study.json").read_text())["scale"] == "smoke"
    assert stamps == {p: p.stat().st_mtime_ns for p in outputs}


def _free_ports(n: int) -> list[int]:
    sockets = [socket.socket() for _ in range(n)]
    for sock in sockets:
        sock.bind(("127.0.0.1", 0))
    ports = [sock.getsockname()[1] for sock in sockets]
    for sock in sockets:
        sock.close()
    return ports


def _wait_for_port(port: int, head: subprocess.Popen) -> None:
    """Wait until ``head`` opens ``port`` (a refused connection is answered at once); fail if it exits first."""
    deadline = time.monotonic() + HANG_S  # only against a hang
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=HANG_S):
            return
        assert head.poll() is None, f"the Ray head exited with status {head.returncode} before it opened port {port}"
        time.sleep(0.5)
    raise AssertionError(f"the Ray head did not open port {port}")


RAY_STUDY = """
import sys
from dataclasses import replace
from sb3_genrl.study import run_study
from sb3_genrl.study.scales import SCALES, task_scale

run_study("hockey", replace(SCALES["smoke"], seeds=1, baseline_episodes=0), sys.argv[1], executor="ray",
          address=sys.argv[2], models=("VAE3",), connect_timeout=float(sys.argv[3]))
"""


@pytest.mark.slow
def test_study_on_a_ray_cluster_started_with_ray_start(tmp_path):
    pytest.importorskip("ray")
    # A real head started as the README says, with token authentication on: RAY_AUTH_MODE=token and the token in
    # RAY_AUTH_TOKEN on the head and on the machine running the study. Ray's socket paths must stay short, hence a
    # temporary folder of its own under /tmp; the head is stopped through its own process, not `ray stop`, which
    # would stop every Ray instance on the machine.
    gcs, client, agent = _free_ports(3)
    token_env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(16)}
    temp = tempfile.mkdtemp(prefix="ray", dir="/tmp")
    head = subprocess.Popen(
        [
            str(Path(sys.executable).parent / "ray"),
            "start",
            "--head",
            f"--port={gcs}",
            "--num-cpus=2",
            "--include-dashboard=false",
            f"--ray-client-server-port={client}",
            f"--dashboard-agent-listen-port={agent}",
            "--disable-usage-stats",
            f"--temp-dir={temp}",
            "--block",
        ],
        env=token_env,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        _wait_for_port(gcs, head)
        address = f"127.0.0.1:{gcs}"
        # Without the token the study stops at its time limit, naming the address and what to set (run beside the
        # study with the token, which works, given a limit no loaded machine reaches).
        no_token = {key: value for key, value in os.environ.items() if not key.startswith("RAY_AUTH")}
        runs = {}
        for name, env, limit in (("refused", no_token, "5"), ("study", token_env, str(HANG_S))):
            with open(tmp_path / f"{name}.err", "w") as stderr:
                runs[name] = subprocess.Popen(
                    [sys.executable, "-c", RAY_STUDY, str(tmp_path / name), address, limit],
                    env=env,
                    stdout=subprocess.DEVNULL,
                    stderr=stderr,
                )
        for run in runs.values():
            run.wait(HANG_S)
        errors = {name: (tmp_path / f"{name}.err").read_text() for name in runs}
        assert runs["refused"].returncode != 0
        assert f"RayConnectionError: no connection to the Ray cluster at {address} within 5 s" in errors["refused"]
        assert "RAY_AUTH_MODE=token" in errors["refused"]
        assert runs["study"].returncode == 0, errors["study"][-3000:]
    finally:
        head.terminate()  # the head drains and stops the processes it started
        try:
            head.wait(90)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait()
        shutil.rmtree(temp, ignore_errors=True)
    rows = json.loads((tmp_path / "study" / "hockey" / "results.json").read_text())
    assert [r["model"] for r in rows] == ["VAE3"] and len(rows[0]["rewards"]) == 1
    assert (tmp_path / "study" / "hockey" / "report.md").exists()


def test_study_rejects_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="unknown task"):
        run_study("golf", "smoke", tmp_path)
    with pytest.raises(ValueError, match="unknown scale"):
        run_study("hockey", "huge", tmp_path)
    with pytest.raises(ValueError, match="unknown models"):
        run_study("hockey", "smoke", tmp_path, models=("VAE10",))
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got 0"):
        run_study("hockey", "smoke", tmp_path, workers=0)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is a file; expected a folder"):
        run_study("hockey", "smoke", tmp_path / "file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # nothing was started


@pytest.mark.slow
def test_quickstart_and_video(tmp_path, cli):
    out = tmp_path / "quick"
    # Without the quickstart's own video (offscreen rendering is slow on a CPU): the video command is tested below.
    code, printed, err = cli(
        "quickstart",
        "--out",
        out,
        "--demo-episodes",
        200,
        "--epochs",
        3,
        "--episodes",
        64,
        "--no-progress-bar",
        "--device",
        "cpu",
        "--no-video",
    )
    assert code == 0, err
    report = (out / "report.md").read_text()
    for name in ("policy/learning_curve.png", "evaluation/precision_recall.png", "vae.pt", "policy/genrl_policy.zip"):
        assert (out / name).exists(), name
    assert "policy.gif" not in report and not (out / "policy.gif").exists()
    assert "**Demonstrations**: 200 valid episodes" in report and "3 epochs" in report
    # The reported distance is the policy's: replayed here on the same 100 goals (seed 0 + EVAL_GOAL_SEED) through the
    # task.
    reported = float(re.search(r"to 100 new goals \(deterministic\): \*\*([0-9.]+) m\*\*", report).group(1))
    replayed = policy_distances(out / "policy" / "genrl_policy.zip", "GenRL/Hockey-v0", 100, EVAL_GOAL_SEED).mean()
    assert reported == pytest.approx(replayed, abs=0.00051)
    assert f"mean distance to 100 new goals is {reported:.3f} m" in printed
    measures = json.loads((out / "evaluation" / "results.json").read_text())[0]
    assert f"precision {measures['precision']:.3f}, recall {measures['recall']:.3f}" in report
    summary = json.loads((out / "policy" / "summary.json").read_text())
    assert summary["episodes"] == 64 and f"{summary['episodes']} episodes" in report
    # with hockey's entry in hyperparams/genrl.yml, its episodes per iteration played together (the fast path's one
    # threaded call, as train-policy's default), and a minibatch of them: GenRL's default of 64 capped at the batch
    _, batch_episodes, kwargs = load_genrl_settings("GenRL/Hockey-v0")
    assert summary["n_envs"] == batch_episodes == 32
    assert summary["genrl_settings"] == genrl_settings(kwargs | {"n_steps": 1, "batch_size": batch_episodes})

    video = tmp_path / "gen.gif"
    code, printed, _ = cli("video", "--task", "hockey", "--generator", out / "vae.pt", "--goals", 1, "--out", video)
    assert code == 0 and video.stat().st_size > 1000 and (tmp_path / "gen_strip.png").exists()
    assert len(re.search(r"rewards (.*)\)", printed).group(1).split(", ")) == 1
    # a frame every other control step, at half the frame rate: half the frames, the same pace, the same episode
    frames = {}
    for every in (1, 2):
        path = tmp_path / f"every{every}.mp4"
        video_args = ("--generator", out / "vae.pt", "--goals", 1, "--every", every, "--out", path)
        code, shown, _ = cli("video", "--task", "hockey", *video_args)
        assert code == 0 and re.search(r"rewards (.*)\)", shown).group(1) == re.search(r"rewards (.*)\)", printed).group(1)
        frames[every] = imageio_ffmpeg.count_frames_and_secs(str(path))
    # each video holds its last frame for half a second (12 and 6 frames); of the episode's frames, the first and
    # every other one after it
    assert frames[2][0] - 6 == (frames[1][0] - 12 + 1) // 2 and frames[2][1] == pytest.approx(frames[1][1], rel=0.1)
    code, printed, _ = cli(
        "video", "--task", "hockey", "--policy", out / "policy", "--goals", 2, "--seed", 7, "--out", tmp_path / "policy.mp4"
    )
    assert code == 0 and (tmp_path / "policy.mp4").stat().st_size > 1000
    rewards = [float(r) for r in re.search(r"rewards (.*)\)", printed).group(1).split(", ")]
    expected = -policy_distances(out / "policy" / "genrl_policy.zip", "GenRL/Hockey-v0", 2, 7)
    np.testing.assert_allclose(rewards, expected, atol=5e-4)  # the video plays the policy on its own goals
    code, _, err = cli("video", "--task", "basketball", "--generator", out / "vae.pt", "--out", tmp_path / "b.gif")
    assert code == 2 and "horizon 69 is not the basketball task's 78" in err
    made = video.read_bytes()  # a video already there is replaced only with --overwrite
    code, _, err = cli("video", "--task", "hockey", "--generator", out / "vae.pt", "--seed", 3, "--out", video)
    assert code == 2 and "already holds a video (gen.gif); pass --overwrite" in err and video.read_bytes() == made
    code, _, _ = cli("video", "--task", "hockey", "--generator", out / "vae.pt", "--seed", 3, "--out", video, "--overwrite")
    assert code == 0 and video.read_bytes() != made

    # A rerun with other settings is refused before any work and names the setting; with the same ones it resumes
    # and does no work.
    outputs = [out / name for name in ("vae.pt", "evaluation/results.json", "policy/summary.json")]
    stamps = [path.stat().st_mtime_ns for path in outputs]
    args = [
        "quickstart",
        "--out",
        out,
        "--demo-episodes",
        200,
        "--episodes",
        64,
        "--no-progress-bar",
        "--device",
        "cpu",
        "--no-video",
    ]
    code, _, err = cli(*args, "--epochs", 4)
    assert code == 2 and f"{out / 'vae.stage.json'}: epochs 3 (recorded) vs 4 (this run)" in err
    code, printed, err = cli(*args, "--epochs", 3)
    assert code == 0, err
    assert all(f"{stage}: already there" in printed for stage in ("demonstrations", "generator", "evaluation", "policy"))
    assert "video:" not in printed
    assert stamps == [path.stat().st_mtime_ns for path in outputs]
    # The resumed run's report gives the times the stages took when they were made, not the rerun's zeros.
    made_in = json.loads((out / "stage_times.json").read_text())
    assert sorted(made_in) == ["demonstrations", "evaluation", "generator", "policy"]
    report = (out / "report.md").read_text()
    assert "3 epochs" in report and ", ".join(f"{k} {v:.0f}" for k, v in made_in.items()) in report


def test_windowed_curve_and_mean_std_over_seeds():
    from sb3_genrl.curves import mean_std_over_seeds, windowed_curve

    episodes, means = windowed_curve(np.arange(10.0), 4)
    np.testing.assert_array_equal(episodes, [4, 8])
    np.testing.assert_array_equal(means, [1.5, 5.5])
    curves = [
        {"episodes": np.array([0.0, 10.0]), "mean_reward": np.array([0.0, 1.0])},
        {"episodes": np.array([0.0, 10.0]), "mean_reward": np.array([0.0, 3.0])},
    ]
    grid, mean, std = mean_std_over_seeds(curves, grid=np.array([0.0, 5.0, 10.0]))
    np.testing.assert_allclose(mean, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(std, [0.0, 0.5, 1.0])


def test_the_quickstart_video_stage_is_done_only_when_its_gif_and_its_strip_exist(tmp_path):
    from sb3_genrl.study.quickstart import _done

    (tmp_path / "policy.gif").write_bytes(b"GIF89a")  # killed between the GIF and the strip
    assert not _done(tmp_path, "video")
    (tmp_path / "policy_strip.png").write_bytes(b"\x89PNG")
    assert _done(tmp_path, "video")


def test_the_quickstart_video_seed_stays_a_valid_seed_for_the_largest_seed():
    from sb3_genrl.checks import MAX_SEED, check_seed
    from sb3_genrl.study.quickstart import _stage_settings

    def video_seed(seed: int) -> int:
        return _stage_settings("hockey", 10, 2, 64, 32, 32, {}, 10, 10, seed, True)["video"]["seed"]

    assert video_seed(0) == 1 and video_seed(7) == 8  # the derivation the committed quickstart results were made with
    assert check_seed(video_seed(MAX_SEED)) != MAX_SEED  # the video of a run with seed 2**32 - 1 no longer fails


@pytest.mark.parametrize(
    ("task", "given", "demonstrations", "episodes"),
    [
        ("hockey", {}, 2000, 3000),  # hockey's own demonstration count, its whole budget
        ("basketball", {}, 4000, 10000),  # the default count, its budget of 20000 capped
        ("basketball", {"demo_episodes": 10, "policy_episodes": 20000}, 10, 20000),  # a user's counts are kept
    ],
)
def test_the_quickstart_makes_the_tasks_counts_unless_given(
    quickstart_settings, tmp_path, task, given, demonstrations, episodes
):
    made = quickstart_settings(tmp_path / "quick", task=task, **given)
    assert made["demonstrations"]["episodes"] == demonstrations
    assert made["policy"]["episodes"] == episodes


def _study_row(name: str, precision: float, score: float, half: float, final: float, prior: float) -> dict:
    return {
        "model": name,
        "type": name[:3],
        "latent_dim": 2,
        "beta": 0.01,
        "info_weight": 0.1,
        "precision": precision,
        "recall": 0.5 + score / 10,
        "delta_1": 0.5,
        "delta_2": 0.4,
        "mean_delta": 0.45 - half / 10,
        "density": 1.0 + final,
        "coverage": 0.5,
        "prior_median": prior,
        "prior_q25": prior - 0.1,
        "prior_q75": prior + 0.1,
        "best_epoch": 4,
        "selection": [[2, 5e-4], [4, 2e-5], [6, 3e-5]],
        "rewards": [score, score - 0.1],
        "score": score,
        "half_rewards": [half],
        "half_score": half,
        "final_rewards": [final],
        "final": final,
        "cpu_seconds": {"generator": 3600.0, "evaluation": 36.0, "genrl": 7200.0},
    }


def test_the_report_leaves_unconverged_generators_out_of_the_correlations_and_states_the_stability(tmp_path):
    from scipy.stats import pearsonr, spearmanr

    from sb3_genrl.study.report import write_task_report

    rng = np.random.default_rng(0)
    rows = [_study_row(f"VAE{i}", 0.9, *rng.normal(size=4)) for i in range(1, 6)]
    rows += [_study_row(f"GAN{i}", 0.5, *rng.normal(size=4)) for i in range(1, 4)]
    rows += [_study_row("GAN4", 0.149, 10.0, 10.0, 10.0, 10.0)]  # not converged: would dominate every correlation
    report = write_task_report("hockey", rows, tmp_path, scale={"prior_draws": 16, "prior_contexts": 64}).read_text()
    assert "left out of every correlation and of the stability: GAN4 (0.149)." in report
    assert "CPU time of the 9 generators' stages: 27.09 h (generator 9.00 h, evaluation 0.09 h, genrl 18.00 h;" in report
    ranked = rows[:-1]
    stability = json.loads((tmp_path / "tables" / "stability.json").read_text())
    expected = spearmanr([r["half_score"] for r in ranked], [r["score"] for r in ranked]).statistic
    assert stability["models"] == 8 and stability["rho"] == pytest.approx(expected, abs=1e-12)
    assert f"**{expected:.3f}** (95% bootstrap interval" in report
    assert stability["low"] <= stability["rho"] <= stability["high"] and stability["stable"] == (expected >= 0.9)
    tables = {(row["group"], row["measure"]): row for row in _csv_rows(tmp_path / "tables" / "correlation.csv")}
    recall = tables[("ALL", "recall")]
    assert int(recall["num_models"]) == 8
    assert float(recall["pearson_r"]) == pytest.approx(
        pearsonr([r["recall"] for r in ranked], [r["score"] for r in ranked]).statistic, abs=1e-12
    )
    final = {row["measure"]: row for row in _csv_rows(tmp_path / "tables" / "prediction_final.csv")}
    assert sorted(final) == sorted(
        ["precision", "recall", "delta_1", "delta_2", "mean_delta", "density", "coverage", "prior_median"]
    )
    assert float(final["prior_median"]["spearman_rho"]) == pytest.approx(
        spearmanr([r["prior_median"] for r in ranked], [r["final"] for r in ranked]).statistic, abs=1e-12
    )
    assert {row["group"] for row in final.values()} == {"ALL"}
    selection = {row["model"]: row for row in _csv_rows(tmp_path / "tables" / "selection.csv")}
    assert selection["GAN4"]["status"] == "not converged" and float(selection["VAE1"]["selection MSE kept"]) == 2e-5
    # errors far below 0.001 keep their digits in the Markdown table, which other tables round to 3 decimals
    assert "| VAE1 | 3 | 0.0005 | 2e-05 | 4 | 3e-05 | 0.900 | ok |" in (tmp_path / "tables" / "selection.md").read_text()
    for name in ("selection_vae", "selection_gan"):
        assert (tmp_path / "plots" / f"{name}.png").stat().st_size > 1000


def test_the_index_pools_the_tasks_as_paper_table_6_once_both_have_finished(tmp_path):
    from scipy.stats import pearsonr, spearmanr

    from sb3_genrl.study.runner import _write_index

    rng = np.random.default_rng(1)
    rows = {
        task: [_study_row(f"VAE{i}", 0.9, *rng.normal(size=4)) for i in range(1, 5)]
        + [_study_row("GAN1", 0.1, 9.0, 9.0, 9.0, 9.0)]
        for task in ("hockey", "basketball")
    }  # GAN1: not converged
    (tmp_path / "hockey").mkdir()
    (tmp_path / "hockey" / "results.json").write_text(json.dumps(rows["hockey"]))
    (tmp_path / "hockey" / "report.md").write_text("# hockey\n")
    _write_index(tmp_path)  # basketball has not finished: no pooled table
    assert (tmp_path / "report.md").read_text() == "# GenRL study\n\n- [hockey](hockey/report.md)\n"
    assert not (tmp_path / "all_tasks.md").exists()
    (tmp_path / "basketball").mkdir()
    (tmp_path / "basketball" / "results.json").write_text(json.dumps(rows["basketball"]))
    (tmp_path / "basketball" / "report.md").write_text("# basketball\n")
    index = _write_index(tmp_path).read_text()
    assert "- [all tasks](all_tasks.md): paper table 6" in index and "- [basketball](basketball/report.md)" in index
    pooled = [r for task in ("hockey", "basketball") for r in rows[task][:4]]
    table = {row["measure"]: row for row in _csv_rows(tmp_path / "all_tasks.csv")}
    assert {row["group"] for row in table.values()} == {"ALL"} and int(table["recall"]["num_models"]) == 8
    for measure in ("recall", "mean_delta"):
        x, y = [r[measure] for r in pooled], [r["score"] for r in pooled]
        assert float(table[measure]["pearson_r"]) == pytest.approx(pearsonr(x, y).statistic, abs=1e-12)
        assert float(table[measure]["spearman_rho"]) == pytest.approx(spearmanr(x, y).statistic, abs=1e-12)
    assert "(hockey 4, basketball 4)" in (tmp_path / "all_tasks.md").read_text()


def test_half_budget_best_reads_the_iterations_within_half_the_episodes():
    from sb3_genrl.study.jobs import half_budget_best

    curve = {"episodes": np.array([16.0, 32, 48, 64]), "mean_reward": np.array([-3.0, -1.0, -0.5, -2.0])}
    assert half_budget_best(curve, 64) == -1.0 and half_budget_best(curve, 100) == -0.5
    assert half_budget_best(curve, 16) == -3.0  # the first iteration already ends past half the budget


def test_each_task_runs_its_own_episodes_per_iteration_and_a_changed_budget_is_refused(tmp_path):
    from dataclasses import replace

    from sb3_genrl.study.runner import _conflicts

    small = SCALES["small"].as_dict()
    for task in ("hockey", "basketball"):
        _, batch_episodes, _ = load_genrl_settings(get_task(task).env_id)
        resolved = task_scale(small, task)
        assert (
            resolved["batch_episodes"] == batch_episodes
            and resolved["policy_episodes"] == SCALES["small"].policy_episodes[task]
            and resolved["seeds"] == SCALES["small"].seeds[task]
        )
    with pytest.raises(ValueError, match="not for 'hockey'"):
        task_scale({**small, "policy_episodes": {"basketball": 10}}, "hockey")
    # A study folder whose policies were recorded with hockey's settings refuses another budget or batch size.
    from sb3_genrl.study.runner import _stages
    from sb3_genrl.utils import atomic_write_json

    hockey = task_scale(small, "hockey")
    for record, wanted, _ in _stages("hockey", tmp_path, hockey, None):
        atomic_write_json(record, wanted)
    assert _conflicts("hockey", hockey, tmp_path) == []
    # The record holds the minibatch GenRL runs with: at most an iteration's episodes, not GenRL's default of 64.
    for task in ("hockey", "basketball"):
        scale = task_scale(small, task)
        [policies] = [wanted for record, wanted, _ in _stages(task, tmp_path / task, scale, None) if "policies" in str(record)]
        wanted = {"hockey": 32, "basketball": 16}[task]
        assert policies["genrl"]["n_steps"] == policies["genrl"]["batch_size"] == scale["batch_episodes"] == wanted, task
    changed = task_scale(replace(SCALES["small"], batch_episodes=64).as_dict(), "hockey")
    [line] = [line for line in _conflicts("hockey", changed, tmp_path) if "policies" in line]
    assert line.startswith(
        f"{tmp_path / 'policies'}: batch_episodes {hockey['batch_episodes']} (recorded) vs 64 (this run), genrl "
    )  # and the GenRL settings, whose n_steps is the batch
    fewer_draws = {**hockey, "prior_draws": 4}
    assert any("prior_draws 16 (recorded) vs 4" in line for line in _conflicts("hockey", fewer_draws, tmp_path))


def test_the_quickstart_refuses_a_training_runs_folder(tmp_path, cli, hockey_generator):
    run = tmp_path / "run"
    code, _, err = cli("train-policy", "--task", "hockey", "--generator", hockey_generator, "--episodes", 32, "--out", run)
    assert code == 0, err
    summary = (run / "summary.json").read_bytes()
    code, _, err = cli("quickstart", "--out", run, "--demo-episodes", 64, "--epochs", 2, "--episodes", 32, "--no-video")
    assert code == 2 and "holds a training run (run_record.json" in err and "choose another --out" in err
    assert (run / "summary.json").read_bytes() == summary and not (run / "demonstrations").exists()
