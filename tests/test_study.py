"""The study (smoke scale, local and Ray executors), the quickstart and the video command."""

import json
from dataclasses import replace

import numpy as np
import pytest

from sb3_genrl.cli import main
from sb3_genrl.study import MODELS, run_study
from sb3_genrl.study.scales import SCALES


@pytest.mark.slow
def test_smoke_study_writes_every_table_and_plot_and_resumes(tmp_path):
    lines = []
    report = run_study("hockey", "smoke", tmp_path, workers=2, log=lines.append)
    root = tmp_path / "hockey"
    assert report == root / "report.md"
    text = report.read_text()
    for section in ("Table 1", "Tables 4-5", "Tables 2-3", "GenRL vs PPO vs SAC"):
        assert section in text
    for name in ("table1_models", "measures", "correlation"):
        assert (root / "tables" / f"{name}.csv").exists() and (root / "tables" / f"{name}.md").exists()
    for name in ("learning_curves_vae", "learning_curves_gan", "precision_recall", "disentanglement"):
        assert (root / "plots" / f"{name}.png").stat().st_size > 1000
    assert (root / "comparison" / "reward_vs_episodes.png").exists()
    assert (root / "comparison" / "table_contacts.png").exists()
    rows = json.loads((root / "results.json").read_text())
    assert sorted(r["model"] for r in rows) == sorted(MODELS)
    for row in rows:
        assert len(row["rewards"]) == SCALES["smoke"].seeds and row["score"] == max(row["rewards"])
        assert 0 <= row["precision"] <= 1 and 0 <= row["recall"] <= 1
    table1 = (root / "tables" / "table1_models.csv").read_text().splitlines()
    assert len(table1) == 1 + 18

    # A rerun finds every result and recomputes nothing: the files are left as they were.
    stamps = {p: p.stat().st_mtime_ns for p in root.glob("policies/*/seed*/summary.json")}
    run_study("hockey", "smoke", tmp_path, workers=1)
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


@pytest.mark.slow
def test_quickstart_and_video(tmp_path):
    out = tmp_path / "quick"
    assert main(["quickstart", "--out", str(out), "--demos", "200", "--epochs", "3", "--episodes", "64"]) == 0
    report = (out / "report.md").read_text()
    assert "GenRL" in report and "cm" in report
    for name in ("policy.gif", "policy_strip.png", "policy/learning_curve.png", "evaluation/precision_recall.png",
                 "vae.pt", "policy/genrl_policy.zip"):
        assert (out / name).exists(), name
    video = tmp_path / "gen.gif"
    assert main(["video", "--task", "hockey", "--generator", str(out / "vae.pt"), "--goals", "2", "--out",
                 str(video)]) == 0
    assert video.stat().st_size > 1000 and (tmp_path / "gen_strip.png").exists()
    assert main(["video", "--task", "basketball", "--generator", str(out / "vae.pt"), "--out", str(video)]) == 2


def test_windowed_curve_and_mean_std_over_seeds():
    from sb3_genrl.callbacks import windowed_curve
    from sb3_genrl.curves import mean_std_over_seeds

    episodes, means = windowed_curve(np.arange(10.0), 4)
    np.testing.assert_array_equal(episodes, [4, 8])
    np.testing.assert_array_equal(means, [1.5, 5.5])
    curves = [{"episodes": np.array([0.0, 10.0]), "mean_reward": np.array([0.0, 1.0])},
              {"episodes": np.array([0.0, 10.0]), "mean_reward": np.array([0.0, 3.0])}]
    grid, mean, std = mean_std_over_seeds(curves, grid=np.array([0.0, 5.0, 10.0]))
    np.testing.assert_allclose(mean, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(std, [0.0, 0.5, 1.0])
