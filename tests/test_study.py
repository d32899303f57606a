"""The study (smoke scale, local and Ray executors), the quickstart and the video command."""

import contextlib
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from sb3_genrl.cli import main
from sb3_genrl.study import MODELS, run_study
from sb3_genrl.study.scales import SCALES
from sb3_genrl.study.state import SettingsConflictError


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

    # The report states the settings the stages recorded.
    smoke = SCALES["smoke"]
    assert f'"demo_episodes": {smoke.demo_episodes}, "generator_epochs": {smoke.generator_epochs},' in text

    # A rerun finds every result and recomputes nothing: the files are left as they were.
    outputs = [*root.glob("policies/*/seed*/summary.json"), *root.glob("generators/*.pt"),
               *root.glob("evaluation/*.json"), *root.glob("comparison/*/summary.json"), root / "demonstrations"]
    stamps = {p: p.stat().st_mtime_ns for p in outputs}
    run_study("hockey", "smoke", tmp_path, workers=1)
    assert stamps == {p: p.stat().st_mtime_ns for p in outputs}

    # Another scale into the same folder is refused before any work, naming the folders and settings that differ.
    with pytest.raises(SettingsConflictError) as error:
        run_study("hockey", "small", tmp_path, workers=1)
    message, small = str(error.value), SCALES["small"]
    assert f"{root / 'demonstrations'}: episodes {smoke.demo_episodes} (recorded) vs {small.demo_episodes}" in message
    assert f"{root / 'generators'}: epochs {smoke.generator_epochs} (recorded) vs {small.generator_epochs}" in message
    assert f"{root / 'policies'}: episodes {smoke.policy_episodes} (recorded) vs {small.policy_episodes}" in message
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


def _wait_for_port(port: int, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
            return
        time.sleep(0.5)
    raise TimeoutError(f"the Ray head did not open port {port} within {seconds} s")


RAY_STUDY = """
import sys
from dataclasses import replace
from sb3_genrl.study import run_study
from sb3_genrl.study.scales import SCALES

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
    head = subprocess.Popen([str(Path(sys.executable).parent / "ray"), "start", "--head", f"--port={gcs}", "--num-cpus=2",
                             "--include-dashboard=false", f"--ray-client-server-port={client}",
                             f"--dashboard-agent-listen-port={agent}", "--disable-usage-stats", f"--temp-dir={temp}",
                             "--block"], env=token_env, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        _wait_for_port(gcs, 120)
        address = f"127.0.0.1:{gcs}"
        # Without the token the study stops within its time limit, naming the address and what to set (run beside
        # the study with the token, which works).
        no_token = {key: value for key, value in os.environ.items() if not key.startswith("RAY_AUTH")}
        runs = {}
        for name, env, limit in (("refused", no_token, "5"), ("study", token_env, "30")):
            with open(tmp_path / f"{name}.err", "w") as stderr:
                runs[name] = subprocess.Popen([sys.executable, "-c", RAY_STUDY, str(tmp_path / name), address, limit],
                                              env=env, stdout=subprocess.DEVNULL, stderr=stderr)
        for run in runs.values():
            run.wait(500)
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


@pytest.mark.slow
def test_quickstart_and_video(tmp_path, capsys):
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

    # A rerun with other settings is refused before any work and names the setting; with the same ones it resumes
    # and does no work.
    outputs = [out / name for name in ("vae.pt", "evaluation/results.json", "policy/summary.json", "policy.gif")]
    stamps = [path.stat().st_mtime_ns for path in outputs]
    capsys.readouterr()
    assert main(["quickstart", "--out", str(out), "--demos", "200", "--epochs", "4", "--episodes", "64"]) == 2
    assert f"{out / 'vae.stage.json'}: epochs 3 (recorded) vs 4 (this run)" in capsys.readouterr().err
    assert main(["quickstart", "--out", str(out), "--demos", "200", "--epochs", "3", "--episodes", "64"]) == 0
    printed = capsys.readouterr().out
    assert all(f"{stage}: already there" in printed for stage in ("demonstrations", "generator", "evaluation",
                                                                  "policy", "video"))
    assert stamps == [path.stat().st_mtime_ns for path in outputs]
    assert "3 epochs" in (out / "report.md").read_text()


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
