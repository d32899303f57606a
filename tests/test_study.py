"""The study (smoke scale through ``genrl study``, the Ray executor), the quickstart and the video command."""

import csv
import json
import re
from dataclasses import replace

import numpy as np
import pytest
from conftest import policy_distances

from sb3_genrl.study import run_study
from sb3_genrl.study.scales import SCALES

SMOKE_MODELS = ("VAE1", "GAN1")  # one of each kind: every table and plot of the study has something to show


def _csv_rows(path):
    with open(path, newline="") as file:
        return list(csv.DictReader(file))


@pytest.mark.slow
def test_smoke_study_writes_every_table_and_plot_and_resumes(tmp_path, cli):
    code, out, err = cli("study", "--task", "hockey", "--scale", "smoke", "--models", *SMOKE_MODELS, "--workers", "1",
                         "--device", "cpu", "--out", tmp_path)
    root = tmp_path / "hockey"
    assert code == 0, err
    assert f"wrote {root / 'report.md'}" in out
    rows = {row["model"]: row for row in json.loads((root / "results.json").read_text())}
    assert sorted(rows) == sorted(SMOKE_MODELS)
    for name, row in rows.items():
        # Each model's row holds its own evaluation file's measures and its policies' best rewards.
        evaluation = json.loads((root / "evaluation" / f"{name}.json").read_text())
        assert all(row[m] == evaluation[m] for m in ("precision", "recall", "delta_1", "delta_2", "mean_delta"))
        summaries = [json.loads((root / "policies" / name / f"seed{s}" / "summary.json").read_text())
                     for s in range(SCALES["smoke"].seeds)]
        assert row["rewards"] == [s["best_mean_reward"] for s in summaries] and row["score"] == max(row["rewards"])
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
    assert [row["method"] for row in comparison] == ["GenRL", "PPO (BC)", "SAC (prefilled)", "PPO on latent",
                                                     "SAC on latent", "TRPO on latent"]
    assert all(row["seeds"] == "1" for row in comparison)
    for name in ("reward_vs_episodes.png", "table_contacts.png"):
        assert (root / "comparison" / name).stat().st_size > 1000
    best = max(rows.values(), key=lambda r: r["score"])
    report = (root / "report.md").read_text()
    assert f"Best generator: **{best['model']}** (best reward {best['score']:.3f}" in report
    for section in ("Table 1", "Tables 4-5", "Tables 2-3", "GenRL vs PPO vs SAC"):
        assert f"## {section}" in report

    # A rerun finds every result and recomputes nothing: the files are left as they were.
    stamps = {p: p.stat().st_mtime_ns for p in root.glob("policies/*/seed*/summary.json")}
    run_study("hockey", "smoke", tmp_path, workers=1, models=SMOKE_MODELS)
    assert stamps == {p: p.stat().st_mtime_ns for p in root.glob("policies/*/seed*/summary.json")}


@pytest.mark.slow
def test_study_on_ray_in_local_mode(tmp_path):
    ray = pytest.importorskip("ray")
    # A local Ray instance (Ray 2.x has no in-process local mode): each generator's job runs as a Ray task.
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        scale = replace(SCALES["smoke"], seeds=1, baseline_episodes=0)
        scale_report = run_study("hockey", scale, tmp_path, executor="ray", models=("VAE3", "GAN6"))
    finally:
        ray.shutdown()
    rows = json.loads((tmp_path / "hockey" / "results.json").read_text())
    assert sorted(r["model"] for r in rows) == ["GAN6", "VAE3"]
    assert all(len(r["rewards"]) == 1 for r in rows)
    assert scale_report.exists()


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
    code, printed, err = cli("quickstart", "--out", out, "--demo-episodes", 200, "--epochs", 3, "--episodes", 64,
                             "--no-progress-bar", "--device", "cpu", "--no-video")
    assert code == 0, err
    report = (out / "report.md").read_text()
    for name in ("policy/learning_curve.png", "evaluation/precision_recall.png", "vae.pt", "policy/genrl_policy.zip"):
        assert (out / name).exists(), name
    assert "policy.gif" not in report and not (out / "policy.gif").exists()
    assert "**Demonstrations**: 200 valid episodes" in report and "3 epochs" in report
    # The reported distance is the policy's: replayed here on the same 100 goals (seed 0 + 12345) through the task.
    reported = float(re.search(r"to 100 new goals \(deterministic\): \*\*([0-9.]+) cm\*\*", report).group(1))
    assert reported == pytest.approx(100 * policy_distances(out / "policy" / "genrl_policy.zip", "GenRL/Hockey-v0",
                                                            100, 12345).mean(), abs=0.051)
    measures = json.loads((out / "evaluation" / "results.json").read_text())[0]
    assert f"precision {measures['precision']:.3f}, recall {measures['recall']:.3f}" in report
    summary = json.loads((out / "policy" / "summary.json").read_text())
    assert summary["episodes"] == 64 and f"{summary['episodes']} episodes" in report

    video = tmp_path / "gen.gif"
    code, printed, _ = cli("video", "--task", "hockey", "--generator", out / "vae.pt", "--goals", 1, "--out", video)
    assert code == 0 and video.stat().st_size > 1000 and (tmp_path / "gen_strip.png").exists()
    assert len(re.search(r"rewards (.*)\)", printed).group(1).split(", ")) == 1
    code, printed, _ = cli("video", "--task", "hockey", "--policy", out / "policy", "--goals", 2, "--seed", 7,
                           "--out", tmp_path / "policy.mp4")
    assert code == 0 and (tmp_path / "policy.mp4").stat().st_size > 1000
    rewards = [float(r) for r in re.search(r"rewards (.*)\)", printed).group(1).split(", ")]
    expected = -policy_distances(out / "policy" / "genrl_policy.zip", "GenRL/Hockey-v0", 2, 7)
    np.testing.assert_allclose(rewards, expected, atol=5e-4)  # the video plays the policy on its own goals
    code, _, err = cli("video", "--task", "basketball", "--generator", out / "vae.pt", "--out", video)
    assert code == 2 and "horizon 69 is not the basketball task's 78" in err


def test_windowed_curve_and_mean_std_over_seeds():
    from sb3_genrl.curves import mean_std_over_seeds, windowed_curve

    episodes, means = windowed_curve(np.arange(10.0), 4)
    np.testing.assert_array_equal(episodes, [4, 8])
    np.testing.assert_array_equal(means, [1.5, 5.5])
    curves = [{"episodes": np.array([0.0, 10.0]), "mean_reward": np.array([0.0, 1.0])},
              {"episodes": np.array([0.0, 10.0]), "mean_reward": np.array([0.0, 3.0])}]
    grid, mean, std = mean_std_over_seeds(curves, grid=np.array([0.0, 5.0, 10.0]))
    np.testing.assert_allclose(mean, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(std, [0.0, 0.5, 1.0])
