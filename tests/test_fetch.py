"""Gymnasium-Robotics' Fetch tasks: the MuJoCo 4.0 fix of their joint helpers, the scripted experts open-loop, and
the workflow (demonstrations, a generator, GenRL, the success rate) on tiny sizes."""

import importlib
import json
import os
import shutil

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from conftest import HANG_S

pytest.importorskip("gymnasium_robotics")

from sb3_genrl.envs import TASKS, get_task  # noqa: E402
from sb3_genrl.envs.demonstrations.fetch import expert_success  # noqa: E402
from sb3_genrl.envs.fetch import FAMILIES, FETCH_IDS, GOAL_BOXES  # noqa: E402
from sb3_genrl.envs.fetch_mujoco import fix_joint_helpers, import_robotics, upstream_test_fails  # noqa: E402

FETCH_TASKS = ("fetch-reach", "fetch-push", "fetch-slide", "fetch-pick-and-place")


def test_joint_helpers_fail_under_this_mujoco_without_the_fix_and_work_with_it():
    import_robotics()
    from gymnasium_robotics.utils import mujoco_utils

    env = gym.make("FetchPush-v4").unwrapped
    model, data = env.model, env.data
    hinge = "robot0:shoulder_pan_joint"
    slide = "robot0:r_gripper_finger_joint"
    free = "object0:joint"
    try:
        importlib.reload(mujoco_utils)  # Gymnasium-Robotics' own helpers
        if upstream_test_fails():
            for helper in (mujoco_utils.get_joint_qpos, mujoco_utils.get_joint_qvel):
                with pytest.raises(AssertionError):
                    helper(model, data, hinge)
            with pytest.raises(AssertionError):
                env.reset(seed=0)
    finally:
        assert fix_joint_helpers() == upstream_test_fails()
    for joint, size in ((hinge, 1), (slide, 1), (free, 7)):
        joint_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        start = model.jnt_qposadr[joint_id]
        np.testing.assert_array_equal(mujoco_utils.get_joint_qpos(model, data, joint), data.qpos[start : start + size])
        mujoco_utils.set_joint_qpos(model, data, joint, data.qpos[start : start + size] + 0.01)
        np.testing.assert_array_equal(
            mujoco_utils.get_joint_qpos(model, data, joint), mujoco_utils.get_joint_qpos(model, data, joint)
        )
    qvel_start = model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, free)]
    mujoco_utils.set_joint_qvel(model, data, free, np.arange(6.0))
    np.testing.assert_array_equal(data.qvel[qvel_start : qvel_start + 6], np.arange(6.0))


@pytest.mark.parametrize("task", FETCH_TASKS)
def test_every_fetch_task_resets_and_steps_through_its_own_id(task):
    spec = get_task(task)
    assert spec.env_id in FETCH_IDS and spec in TASKS.values() and gym.spec(spec.env_id).max_episode_steps == 50
    env = gym.make(spec.env_id)
    assert type(env.unwrapped).__module__.startswith("gymnasium_robotics.envs.fetch")  # Gymnasium-Robotics' own env
    obs, _ = env.reset(seed=0)
    for _ in range(50):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert truncated and not terminated and reward in (0.0, -1.0) and "is_success" in info
    low, high = GOAL_BOXES[task.removeprefix("fetch-").title().replace("-", "").replace("Pickandplace", "PickAndPlace")]
    goals = np.array([env.reset(seed=seed)[0]["desired_goal"][:2] for seed in range(20)])
    assert np.all(spec.in_goal_region(goals))


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_the_aims_cover_the_goal_region_widened_by_the_family_margin(name):
    family = FAMILIES[name]
    env = gym.make(family.env_id).unwrapped
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    aims = np.array([family.sample_aim(rng, env) for _ in range(4000)])
    low, high = (np.asarray(corner) for corner in GOAL_BOXES[name])
    margin = family.aim_margin
    assert margin >= 0.02
    # inside the widened region, and reaching its edges on every side (4000 uniform draws: within 1.5 cm)
    assert np.all(aims[:, :2] >= low - margin) and np.all(aims[:, :2] <= high + margin)
    np.testing.assert_allclose(aims[:, :2].min(0), low - margin, atol=0.015)
    np.testing.assert_allclose(aims[:, :2].max(0), high + margin, atol=0.015)
    heights = aims[:, 2] - env.initial_gripper_xpos[2]
    if name == "Reach":  # the env's heights: the gripper's start +- 0.15, widened too
        assert np.all(np.abs(heights) <= 0.15 + margin) and np.abs(heights).max() > 0.15 + margin - 0.015
    elif name == "PickAndPlace":  # on the table, or up to 0.45 above it, as the env's own goals
        above = aims[:, 2] - env.height_offset
        assert np.all((above >= 0) & (above <= 0.45)) and np.mean(above == 0) > 0.4
    else:
        np.testing.assert_array_equal(aims[:, 2], env.height_offset)


@pytest.mark.parametrize("order", ["sb3_genrl.envs, gymnasium_robotics", "gymnasium_robotics, sb3_genrl.envs"])
def test_fetch_ids_reset_whichever_of_the_two_packages_is_imported_first(order):
    # a fresh interpreter: Gymnasium-Robotics imported after sb3_genrl registers its own, unfixed entry points again
    import subprocess
    import sys

    code = (
        f"import {order}\nimport gymnasium as gym\nenv = gym.make('FetchPush-v4')\nenv.reset(seed=0)\n"
        "print(type(env.unwrapped).__module__)"
    )
    result = subprocess.run([sys.executable, "-W", "always", "-c", code], capture_output=True, text=True, timeout=HANG_S)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "gymnasium_robotics.envs.fetch.push"
    assert "Overriding environment" not in result.stderr


@pytest.mark.parametrize(("task", "least"), [("fetch-reach", 1.0), ("fetch-push", 0.8), ("fetch-pick-and-place", 1.0)])
def test_the_scripted_experts_solve_random_initial_states_open_loop(task, least):
    assert expert_success(task, 10, seed=777)["success_rate"] >= least


def check_her_episodes(arrays):
    """As SAC+HER's demonstrations: the achieved goal read from the observation is the env's own (the stored
    reached point is the env's achieved_goal at the end), the desired goal the aim, the rewards the env's compute_reward."""
    from sb3_genrl.baselines.her import fetch_goal_episodes

    episodes = fetch_goal_episodes("fetch-push", arrays)
    np.testing.assert_allclose(episodes["achieved_goal"][:, -1], arrays["reached"], rtol=1e-6)
    np.testing.assert_allclose(episodes["desired_goal"][:, 0], arrays["sampled_goals"], rtol=1e-6)
    distances = np.linalg.norm(episodes["achieved_goal"][:, 1:] - episodes["desired_goal"][:, 1:], axis=-1)
    np.testing.assert_array_equal(episodes["rewards"], -(distances > 0.05).astype(float))
    assert np.all(episodes["rewards"][:, -1] == 0.0) and np.any(episodes["rewards"] == -1.0)


def test_demonstrations_generator_and_genrl_on_fetch_push(tmp_path, cli):
    from sb3_genrl.envs.demonstrations import make_demonstrations

    from sb3_genrl.data import dataset_info, load_arrays
    from sb3_genrl.generative import train_generator
    from sb3_genrl.genrl import GenRL

    dataset = make_demonstrations("fetch-push", 12, tmp_path / "demos", seed=3, n_threads=1, progress_bar=False)
    arrays = load_arrays(dataset)
    assert dataset_info(dataset)["episodes"] == 12 and arrays["actions"].shape == (12, 50, 4)
    assert np.all(np.linalg.norm(arrays["reached"] - arrays["sampled_goals"], axis=1) < 0.05)  # each reached its aim
    # the stored goal is the reached point, and the last step's reward for it is 0
    np.testing.assert_allclose(arrays["observations"][:, 0, :3], arrays["reached"], rtol=1e-6)
    assert np.all(arrays["rewards"][:, -1] == 0.0)
    # the same seed gives the same set, however many worker processes play it
    again = load_arrays(make_demonstrations("fetch-push", 12, tmp_path / "again", seed=3, n_threads=2, progress_bar=False))
    np.testing.assert_array_equal(again["actions"], arrays["actions"])
    check_her_episodes(arrays)

    generator = train_generator(dataset, preset="VAE-FETCH", epochs=2, seed=0, out=tmp_path / "vae.pt", progress_bar=False)
    # the task's entry learns from demonstrations: refused without them, before any work, saying how to make them
    policy = [
        "train-policy",
        "--task",
        "fetch-push",
        "--generator",
        tmp_path / "vae.pt",
        "--episodes",
        32,
        "--batch-episodes",
        16,
        "--device",
        "cpu",
        "--no-progress-bar",
        "--out",
        tmp_path / "policy",
    ]
    code, _, err = cli(*policy)
    assert code == 2 and "--data DIR" in err and "`genrl demos --task fetch-push --episodes 4000 --out DIR`" in err
    assert not (tmp_path / "policy").exists()
    small = {
        "hindsight_kwargs": {"history": 2, "regression_steps": 4},
        "callback": [{"sb3_genrl.genrl.demonstrations.DemonstrationCallback": {"fit_steps": 300}}],
    }
    code, _, err = cli(*policy, "--data", dataset, "--genrl-kwargs", json.dumps(small))
    assert code == 0, err
    from sb3_genrl.data.fingerprints import dataset_fingerprint

    record = json.loads((tmp_path / "policy" / "run_record.json").read_text())
    assert dataset_fingerprint(dataset) in json.dumps(record)  # the demonstrations are part of the run's identity
    model = GenRL.load(tmp_path / "policy" / "genrl_policy.zip", generator=generator, device="cpu")
    # the fit of the mean to each demonstration's posterior mean at its context
    from sb3_genrl.genrl.demonstrations import DemonstrationCallback, fit_mean_to_demonstrations

    contexts = arrays["observations"][:, 0]
    latents = generator.encode(arrays["actions"])[0]
    fresh = GenRL(gym.make("FetchPush-v4"), generator, seed=0, device="cpu")

    def error(genrl):
        return np.mean((genrl.predict(contexts, deterministic=True)[0] - latents) ** 2)

    before = error(fresh)
    assert error(model) < 0.5 * before  # the run's own fit and kept demonstrations
    pulls = DemonstrationCallback(dataset).pulls(generator, fresh.observation_space, fresh.latent_clip)
    fitted = fit_mean_to_demonstrations(fresh.policy, *pulls, steps=300)
    assert fitted["demonstrations"] == 12 and error(fresh) < 0.2 * before and fitted["last_loss"] < fitted["first_loss"]
    evaluation = get_task("fetch-push").evaluate(model, "fetch-push", episodes=3, seed=5)
    assert evaluation["success_rate"] == np.mean(evaluation["successes"]) and len(evaluation["distances"]) == 3
    assert all((d < 0.05) == s for d, s in zip(evaluation["distances"], evaluation["successes"], strict=True))
    # near the policy: its deterministic actions replayed open-loop solve what the wrapper's step path solved
    from sb3_genrl.envs.demonstrations.fetch import policy_neighbourhood_success

    near = policy_neighbourhood_success(model, "fetch-push", 3, 2, 5)
    assert near["deterministic_solved"] == evaluation["successes"] and len(near["solving_draws"]) == 3
    assert near["spread"] == pytest.approx(float(model.policy.log_std.detach().exp().mean()), rel=1e-5)


def test_the_generators_limit_counts_the_draws_that_solve_each_state():
    from sb3_genrl.envs.demonstrations.fetch import prior_best_success
    from sb3_genrl.envs.fetch import reach_expert

    import_robotics()  # the fix, whatever imported Gymnasium-Robotics first
    states, draws, seed = 2, 4, 123
    solving = (3, 1)  # the first draws of each state that play the expert aimed at the state's goal

    class IndexGenerator:  # draw i's latent action is i; the first solving[state] draws of a state play the expert
        def sample_prior(self, n, rng):
            return np.arange(n, dtype=np.float64)[:, None]

        def decode(self, alpha):
            env = gym.make("FetchReach-v4")
            out = []
            for i in alpha[:, 0].astype(int):
                obs, _ = env.reset(seed=int(seed + i // draws))
                good = i % draws < solving[i // draws]
                out.append(reach_expert(obs["observation"], obs["desired_goal"]) if good else np.zeros((50, 4)))
            return np.array(out)

    result = prior_best_success(IndexGenerator(), "fetch-reach", states, draws, seed)
    assert result["solving_draws"] == list(solving)  # the zero actions never reach a goal 15 cm away or more
    assert result["success_rate"] == 1.0 and result["best_of"]["1"] == pytest.approx(np.mean(solving) / draws)


def test_the_results_table_labels_a_partial_run_with_the_episodes_reached(tmp_path):
    from benchmarks.fetch_results import main

    run = {
        "seed": 0,
        "finished": False,
        "curve_episodes": [512, 1024],
        "curve_env_steps": [25600, 51200],
        "curve_success": [0.1, 0.2],
    }
    done = dict(run, seed=1, finished=True, final_success=0.4, curve_success=[0.3, 0.4])
    result = {
        "settings": {"episodes": 3000},
        "complete": False,
        "runs": [run, done],
        "reconstruction": {"success_rate": 0.6},
        "generator_limit": {"success_rate": 0.7, "best_of": {"1": 0.1}},
    }
    (tmp_path / "fetch_fetch-push.json").write_text(json.dumps(result))
    main(["--results", str(tmp_path)])
    line = next(line for line in (tmp_path / "fetch.md").read_text().splitlines() if line.startswith("| fetch-push"))
    assert "partial: seed 0: 1024 (running), seed 1: 1024" in line and "0.400 ± 0.000 (1 seed)" in line
    assert (tmp_path / "fetch_curves.png").stat().st_size > 0
    # SAC+HER's JSON (benchmarks/fetch_sac_her.py): its finished seeds' mean, the buffer's demonstrations, the budget
    sac = {
        "settings": {"n_timesteps": 25600},
        "demonstrations": 4000,
        "complete": False,
        "runs": [done, dict(done, seed=2, final_success=0.8), run],
    }
    (tmp_path / "fetch_sac_her_fetch-push_demos.json").write_text(json.dumps(sac))
    main(["--results", str(tmp_path)])
    text = (tmp_path / "fetch.md").read_text()
    assert (
        "| fetch-push | 4000 | 0.600 ± 0.200 (2 seeds) | 512 | partial: seed 1: 1024, seed 2: 1024, seed 0: 1024 "
        "(running) |" in text
    )


def test_tqc_progress_read_from_the_logs_is_kept_for_a_machine_without_them(tmp_path):
    from benchmarks.fetch_results import main

    result = {"settings": {"episodes": 3000}, "complete": False, "runs": [], "reconstruction": {"success_rate": 0.6}}
    (tmp_path / "fetch_fetch-push.json").write_text(json.dumps(result))
    logs = tmp_path / "tqc"
    run = logs / "FetchPush-v4_seed0" / "segment_1"
    run.mkdir(parents=True)
    np.savez(run / "evaluations.npz", successes=np.array([[0.0, 0.0], [1.0, 0.0]]))
    (logs / "FetchPush-v4_seed0_segments.csv").write_text(f"folder,env_steps_total\n{run},5000\n")
    main(["--results", str(tmp_path), "--tqc", str(logs)])
    row = "| FetchPush-v4_seed0 | 100 | 5000 | 0.500 |"  # the last evaluation: 1 of 2 episodes
    assert row in (tmp_path / "fetch.md").read_text()
    import shutil

    shutil.rmtree(logs)  # a fresh clone: the logs are gone, the kept progress is shown
    main(["--results", str(tmp_path)])
    assert row in (tmp_path / "fetch.md").read_text()
    # a fresh machine's logs: Push started again (less far) and a new Slide run; Push keeps its furthest row
    for name, steps in (("FetchPush-v4_seed0", 2500), ("FetchSlide-v4_seed0", 2500)):
        run = logs / name / "segment_1"
        run.mkdir(parents=True)
        np.savez(run / "evaluations.npz", successes=np.array([[0.0, 0.0]]))
        (logs / f"{name}_segments.csv").write_text(f"folder,env_steps_total\n{run},{steps}\n")
    main(["--results", str(tmp_path), "--tqc", str(logs)])
    text = (tmp_path / "fetch.md").read_text()
    assert row in text and "| FetchSlide-v4_seed0 | 50 | 2500 | 0.000 |" in text
    assert "FetchPush-v4_seed0 | 50 |" not in text


def test_new_runs_keep_the_generator_stages_and_drop_what_the_old_runs_measured(tmp_path):
    from benchmarks.fetch import arguments, settings_of, start

    out, work = tmp_path / "fetch_fetch-push.json", tmp_path / "work"
    args = arguments(["--task", "fetch-push", "--out", str(out), "--work", str(work)])
    settings = settings_of(args)
    # the recorded settings are those the runs use: the entry's episodes per iteration as n_steps
    assert settings["genrl_settings"]["n_steps"] == settings["batch_episodes"] == 32
    old = dict(
        settings, genrl_settings=dict(settings["genrl_settings"], hindsight_kwargs={"history": 60, "regression_steps": 64})
    )
    measures = {
        "generator": {"generator": "vae.pt"},
        "reconstruction": {"success_rate": 0.7},
        "generator_limit": {"success_rate": 0.9},
    }
    out.write_text(
        json.dumps(
            {
                "settings": old,
                "runs": [{"seed": 0, "finished": True}],
                "complete": True,
                "policy_neighbourhood": {"policy_seed": 0},
                "final_success_mean": 0.8,
                **measures,
            }
        )
    )
    (work / "seed_0").mkdir(parents=True)
    with pytest.raises(SystemExit, match="differs in genrl_settings"):
        start(args)
    args.new_runs = True
    result = start(args)
    assert result["runs"] == [] and result["complete"] is False and result["settings"] == settings
    assert {key: result[key] for key in measures} == measures  # the generator's stages are kept
    assert "policy_neighbourhood" not in result and "final_success_mean" not in result  # measured on the old runs
    assert not (work / "seed_0").exists()


def test_the_benchmark_keeps_the_generator_whose_fitted_mean_solves_the_most_tuning_states(tmp_path, monkeypatch):
    from benchmarks import fetch

    scores = {"vae_seed0.pt": 0.25, "vae_seed1.pt": 0.75, "vae_seed2.pt": 0.5}
    scored = []

    def score(task, path, dataset, states, seed):  # the fit is tested above; here: which file is kept
        scored.append((os.path.basename(path), states, seed))
        return scores[os.path.basename(path)]

    monkeypatch.setattr(fetch, "fitted_mean_success", score)
    out, work = tmp_path / "fetch.json", tmp_path / "work"
    argv = [
        "--task",
        "fetch-push",
        "--demos",
        "6",
        "--epochs",
        "1",
        "--generator-seeds",
        "3",
        "--selection-states",
        "4",
        "--out",
        str(out),
        "--work",
        str(work),
    ]
    args = fetch.arguments(argv)
    result = fetch.start(args)
    path = fetch.generator_stage(args, result, lambda: fetch.write_result(str(out), result))
    from sb3_genrl.hyperparams import TUNING_GOAL_SEED

    assert scored == [(f"vae_seed{seed}.pt", 4, TUNING_GOAL_SEED) for seed in range(3)]
    record = json.loads(out.read_text())["generator"]
    assert record["kept_seed"] == 1 and [c["fitted_mean_tuning_success"] for c in record["candidates"]] == [0.25, 0.75, 0.5]
    assert (work / "vae.pt").read_bytes() == (work / "vae_seed1.pt").read_bytes() and path == str(work / "vae.pt")
    assert record["demonstration_info"]["episodes"] == 6
    # resumed: nothing is trained or scored again
    scored.clear()
    args = fetch.arguments(argv)
    assert fetch.generator_stage(args, fetch.start(args), lambda: None) == path and scored == []
    assert record["demonstration_info"]["aim_margin"] == get_task("fetch-push").demonstration_recipe["aim_margin"]


def test_the_benchmark_refuses_demonstrations_of_another_recipe(tmp_path, monkeypatch):
    from benchmarks import fetch
    from benchmarks.fetch_results import status
    from sb3_genrl.data import dataset_info

    monkeypatch.setattr(fetch, "fitted_mean_success", lambda *args: 0.5)
    out, work = tmp_path / "fetch.json", tmp_path / "work"
    argv = ["--task", "fetch-reach", "--demos", "6", "--epochs", "1", "--generator-seeds", "1", "--out", str(out)]
    args = fetch.arguments([*argv, "--work", str(work)])
    result = fetch.start(args)
    fetch.generator_stage(args, result, lambda: fetch.write_result(str(out), result))
    data = work / "demonstrations"
    assert dataset_info(data)["aim_margin"] == 0.05 == result["settings"]["demonstration_recipe"]["aim_margin"]
    # a dataset left by a version whose aims spread over another region is not taken into a new run
    (tmp_path / "other").mkdir()
    shutil.copytree(data, tmp_path / "other" / "demonstrations")
    info_file = tmp_path / "other" / "demonstrations" / "data" / "metadata.json"
    metadata = json.loads(info_file.read_text())
    metadata["genrl"]["aim_margin"] = 0.02
    info_file.write_text(json.dumps(metadata))
    assert dataset_info(tmp_path / "other" / "demonstrations")["aim_margin"] == 0.02
    args = fetch.arguments([*argv, "--work", str(tmp_path / "other"), "--overwrite"])
    with pytest.raises(SystemExit, match="aim_margin 0.02 \\(recorded\\) vs 0.05"):
        fetch.generator_stage(args, fetch.start(args), lambda: None)
    assert not (tmp_path / "other" / "vae.pt").exists()
    # a JSON of an earlier version, which did not record the recipe: its demonstrations had aims widened by 2 cm
    recorded = json.loads(out.read_text())
    del recorded["settings"]["demonstration_recipe"]
    out.write_text(json.dumps(recorded))
    with pytest.raises(SystemExit, match="differs in demonstration_recipe"):
        fetch.start(fetch.arguments([*argv, "--work", str(work), "--new-runs"]))
    recorded["complete"] = True
    assert status(recorded, "fetch-reach") == "complete; former settings (demonstration recipe differ)"
    recorded["settings"]["demonstration_recipe"] = {"aim_margin": 0.05}
    assert status(recorded, "fetch-reach") == "complete"


def test_the_results_table_says_which_runs_used_former_settings():
    from benchmarks.fetch_results import status
    from sb3_genrl.run.train import genrl_settings
    from sb3_genrl.study.quickstart import task_settings

    _, batch_episodes, genrl_kwargs = task_settings("fetch-push")
    now = genrl_settings(genrl_kwargs | {"n_steps": batch_episodes, "batch_size": batch_episodes})  # GenRL's minibatch
    result = {"complete": True, "runs": [], "settings": {"batch_episodes": batch_episodes, "genrl_settings": now}}
    assert status(result, "fetch-push") == "complete"
    result["settings"]["genrl_settings"] = dict(now, n_steps=64)  # as older files record it: not a difference
    assert status(result, "fetch-push") == "complete"
    result["settings"]["genrl_settings"] = dict(now, hindsight_kwargs={"history": 60, "regression_steps": 64})
    assert status(result, "fetch-push") == "complete; former settings (hindsight_kwargs differ)"
    # the generator's recipe: the one recorded (or, for files that record only the preset's name, the former one)
    from sb3_genrl.generative.presets import resolve_generator_spec

    result["settings"] |= {"genrl_settings": now, "generator": "trained", "preset": "VAE-FETCH"}
    assert status(result, "fetch-push") == "complete; former settings (generator recipe differ)"
    result["settings"]["generator_recipe"] = resolve_generator_spec("VAE-FETCH")
    assert status(result, "fetch-push") == "complete"
    result["settings"]["generator_recipe"] = dict(resolve_generator_spec("VAE-FETCH"), path_weight=4.0)
    assert status(result, "fetch-push") == "complete; former settings (generator recipe differ)"


def test_sac_her_resumes_only_a_run_of_the_same_settings(tmp_path):
    from sb3_genrl.envs.demonstrations import make_demonstrations

    from benchmarks import fetch_sac_her

    data = make_demonstrations("fetch-reach", 4, tmp_path / "demos", seed=3, n_threads=1, progress_bar=False)
    out = tmp_path / "sac.json"
    # a file of an earlier version records no recipe: its demonstrations aimed 2 cm beyond the goal region, Reach's
    # now 5 cm
    out.write_text(json.dumps({"benchmark": "fetch_sac_her_fetch-reach_demos", "eval_states": 7, "runs": []}))
    with pytest.raises(
        SystemExit, match="differs in demonstration_recipe, demonstrations, eval_every, eval_seed, eval_states, settings"
    ):
        fetch_sac_her.main(
            [
                "--task",
                "fetch-reach",
                "--variant",
                "demos",
                "--data",
                str(data),
                "--out",
                str(out),
                "--work",
                str(tmp_path / "work"),
            ]
        )
    assert not (tmp_path / "work").exists() and json.loads(out.read_text())["eval_states"] == 7  # nothing touched


def test_sac_her_checkpoints_between_evaluations_and_a_stopped_seed_resumes_from_there(tmp_path, monkeypatch):
    from sb3_genrl.envs.demonstrations import make_demonstrations

    from benchmarks import fetch_sac_her
    from sb3_genrl.utils import read_checkpoint

    data = make_demonstrations("fetch-reach", 2, tmp_path / "demos", seed=3, n_threads=1, progress_bar=False)
    out, work = tmp_path / "sac.json", tmp_path / "work"
    argv = [
        "--task",
        "fetch-reach",
        "--variant",
        "demos",
        "--data",
        str(data),
        "--out",
        str(out),
        "--work",
        str(work),
        "--seeds",
        "0",
        "--steps",
        "150",
        "--eval-every",
        "3",
        "--eval-states",
        "2",
    ]
    fetch_sac_her.main(argv + ["--checkpoint-every", "1"])
    # a checkpoint after each of the first two episodes (the run ends with the third), none at an evaluation
    state = read_checkpoint(work / "demos_seed_0" / "checkpoint")
    assert state["episodes"] == 2 and state["steps"] == 100
    # as if stopped after episode 2: the seed resumes from that checkpoint, plays one episode, and evaluates it
    result = json.loads(out.read_text())
    result["runs"][0] |= {"finished": False, "curve_episodes": [], "curve_env_steps": [], "curve_success": []}
    out.write_text(json.dumps(result))
    loaded = []
    load = fetch_sac_her.SAC.load
    monkeypatch.setattr(fetch_sac_her.SAC, "load", lambda path, **kwargs: loaded.append(path) or load(path, **kwargs))
    fetch_sac_her.main(argv)
    result = json.loads(out.read_text())
    row = result["runs"][0]
    assert loaded == [state["paths"]["model"]]
    assert row["finished"] and row["curve_episodes"] == [3] and row["env_steps"] == 150
    # one seed of the benchmark's three: the JSON stays partial, and the table says how far each seed got
    from benchmarks.fetch_results import all_seeds_finished, status

    assert result["complete"] is False and status(result) == "partial: seed 0: 3"
    others = [dict(row, seed=seed) for seed in (1, 2)]
    assert all_seeds_finished(dict(result, runs=[row, *others]))
    assert not all_seeds_finished(dict(result, runs=[row, others[0], dict(others[1], finished=False)]))


def test_the_scorecard_benchmark_scores_each_generator_then_trains_genrl_on_it_and_resumes(tmp_path, monkeypatch):
    from sb3_genrl.envs.demonstrations import make_demonstrations
    from scipy import stats

    from benchmarks import fetch_scorecard
    from sb3_genrl.generative import load
    from sb3_genrl.metrics.prior_rollout import prior_rollout

    data, work, out = tmp_path / "demos", tmp_path / "work", tmp_path / "scorecard.json"
    make_demonstrations("fetch-reach", 6, str(data), seed=0, n_threads=1, progress_bar=False)
    argv = [
        "--task",
        "fetch-reach",
        "--data",
        str(data),
        "--variants",
        "",
        "latent_dim=3",
        "path_weight=0,beta=0.01",
        "--epochs",
        "1",
        "--episodes",
        "32",
        "--eval-states",
        "2",
        "--tuning-states",
        "2",
        "--contexts",
        "2",
        "--draws",
        "2",
        "--pr-samples",
        "6",
        "--dwpr-samples",
        "4",
        "--work",
        str(work),
        "--out",
        str(out),
    ]
    fetch_scorecard.main(argv)
    result = json.loads(out.read_text())
    rows = {row["variant"]: row for row in result["rows"]}
    assert list(rows) == ["", "latent_dim=3", "path_weight=0,beta=0.01"]
    assert rows["latent_dim=3"]["spec"] == {"latent_dim": 3, "beta": 0.001, "path_weight": 1.0}
    assert rows["path_weight=0,beta=0.01"]["spec"] == {"latent_dim": 10, "beta": 0.01, "path_weight": 0.0}
    small = load(str(work / "latent_dim-3" / "vae.pt"), device="cpu")
    assert small.latent_dim == 3
    expected = prior_rollout(small, "fetch-reach", contexts=2, draws=2).summary()["prior_success"]
    assert rows["latent_dim=3"]["prior_success"] == expected
    assert all(row["episodes"] == 32 and 0 <= row["final_success"] <= 1 for row in rows.values())
    assert len(result["correlation"]) == len(fetch_scorecard.MEASURES)  # one group (ALL), every measure
    # resumed: nothing is trained again; other settings are refused
    monkeypatch.setattr(fetch_scorecard, "generator_row", lambda *a: pytest.fail("a finished generator was redone"))
    fetch_scorecard.main(argv)
    assert json.loads(out.read_text())["rows"] == result["rows"]
    with pytest.raises(SystemExit, match="episodes differ"):
        fetch_scorecard.main([*argv[:-2], "--episodes", "64", "--out", str(out)])
    # the correlations, against scipy on rows whose success differs
    args = fetch_scorecard.arguments(argv)
    synthetic = [
        {**row, "model": name, "final_success": success, "recall": recall}
        for row, name, success, recall in zip(
            result["rows"] * 2, "ABCDEF", (0.1, 0.5, 0.3, 0.9, 0.2, 0.6), (0.2, 0.6, 0.5, 0.8, 0.1, 0.7), strict=False
        )
    ]
    fetch_scorecard.write(args, {**result, "rows": synthetic})
    recall = next(row for row in json.loads(out.read_text())["correlation"] if row["measure"] == "recall")
    success, values = [row["final_success"] for row in synthetic], [row["recall"] for row in synthetic]
    assert recall["pearson_r"] == pytest.approx(stats.pearsonr(values, success)[0])
    assert recall["spearman_rho"] == pytest.approx(stats.spearmanr(values, success)[0])
    assert "| ALL | recall | 6 |" in out.with_suffix(".md").read_text()


def test_the_fit_limit_benchmark_picks_each_states_nearest_solving_draw_and_replays_as_the_step_path_plays():
    import gymnasium as gym
    from sb3_genrl.envs.demonstrations.fetch import replay_success

    from benchmarks.fetch_fit_limit import anchored_targets, solving_targets
    from sb3_genrl.generative import make_generator
    from sb3_genrl.wrappers import LatentActionWrapper

    rng = np.random.default_rng(0)
    drawn, mean = rng.normal(size=(4, 5, 3)), rng.normal(size=(4, 3))
    solved = rng.random((4, 5)) < 0.5
    solved[2] = False  # a state no draw solves is left out
    solved[3] = [False, True, False, False, False]
    nearest, average = solving_targets(drawn, solved, mean)
    states = [i for i in range(4) if solved[i].any()]
    assert len(nearest) == len(average) == len(states)
    for row, i in enumerate(states):  # brute force
        candidates = [j for j in range(5) if solved[i, j]]
        best = min(candidates, key=lambda j: float(np.sum((drawn[i, j] - mean[i]) ** 2)))
        np.testing.assert_allclose(nearest[row], drawn[i, best], rtol=1e-6)
        np.testing.assert_allclose(average[row], drawn[i, candidates].mean(axis=0), rtol=1e-6)
    np.testing.assert_allclose(nearest[-1], drawn[3, 1], rtol=1e-6)
    # anchored: the mean where it solves (state 2 has no solving draw), else the nearest solving draw
    solves = np.array([True, False, True, False])
    kept, targets = anchored_targets(solved.any(axis=1), nearest, mean, solves)
    expected = [mean[i] if solves[i] else nearest[states.index(i)] for i in range(4) if solves[i] or i in states]
    assert kept.tolist() == [True, True, True, True] and len(targets) == len(expected)
    np.testing.assert_allclose(targets, expected, rtol=1e-6)
    kept, targets = anchored_targets(solved.any(axis=1), nearest, mean, np.zeros(4, dtype=bool))
    assert kept.tolist() == [True, True, False, True]
    np.testing.assert_allclose(targets, nearest, rtol=1e-6)
    # replay_success plays what the wrapper's step path plays from the same reset seeds: the same end, the same success
    from sb3_genrl.envs.demonstrations.fetch import _replay

    generator = make_generator("VAE-FETCH", horizon=50, action_dim=4, device="cpu")
    env = LatentActionWrapper(gym.make("FetchReach-v4"), generator)
    latents = np.clip(rng.normal(size=(3, generator.latent_dim)), env.action_space.low, env.action_space.high).astype(
        np.float32
    )
    stepped, distances = [], []
    for i, latent in enumerate(latents):
        env.reset(seed=20 + i)
        stepped.append(bool(env.step(latent)[4]["is_success"]))
        task = env.unwrapped
        distances.append(float(np.linalg.norm(task._get_obs()["achieved_goal"] - task.goal)))
    env.close()
    assert replay_success(generator, "fetch-reach", latents, [20, 21, 22]).tolist() == stepped
    actions = np.clip(generator.decode(latents), -1.0, 1.0).astype(np.float32)
    replayed = [distance for _, distance in _replay("FetchReach-v4", actions, [20, 21, 22], [None] * 3, 1)]
    np.testing.assert_allclose(replayed, distances, atol=1e-9)


def test_the_fit_limit_benchmark_checks_its_fit_variants_before_any_work():
    import argparse

    from benchmarks.fetch_fit_limit import variants

    assert variants('[{"steps": 8000}, {"net_arch": [128, 128], "learning_rate": 1}]') == [
        {"steps": 8000},
        {"net_arch": [128, 128], "learning_rate": 1},
    ]
    for bad in (
        '{"steps": 8000}',
        '[{"step": 8000}]',
        '[{"steps": 0}]',
        '[{"net_arch": [0]}]',
        '[{"steps": 1.5}]',
        '[{"batch_size": "256"}]',
        "[{steps: 1}]",
    ):
        with pytest.raises(argparse.ArgumentTypeError):
            variants(bad)


def test_the_ranking_benchmark_plays_the_candidate_its_critic_ranks_first():
    from benchmarks.fetch_ranking import ranked_first

    rng = np.random.default_rng(1)
    scores, solved = rng.random((50, 16)), rng.random((50, 16)) < 0.5
    for k in (1, 4, 16):  # brute force: each state's highest-scoring candidate among its first k
        expected = np.mean([solved[i, max(range(k), key=lambda j: scores[i, j])] for i in range(50)])
        assert ranked_first(scores, solved, k) == pytest.approx(expected)
    kept = np.mean([solved[i, 0] if scores[i, 0] >= 0.7 else solved[i, int(np.argmax(scores[i]))] for i in range(50)])
    assert ranked_first(scores, solved, 16, keep_mean=0.7) == pytest.approx(kept)
    assert ranked_first(scores, solved, 16, keep_mean=0.0) == pytest.approx(solved[:, 0].mean())  # always the mean


def test_a_resumed_benchmark_seed_keeps_the_monitors_rows_up_to_its_checkpoint(tmp_path, monkeypatch):
    """A seed of benchmarks/fetch.py that resumes from its checkpoint plays the episodes after it again: the Monitor
    file keeps one row per episode of the finished run, not the first try's rows too."""
    import argparse

    from sb3_genrl.envs.demonstrations import make_demonstrations

    from benchmarks import fetch_seed
    from benchmarks.fetch_seed import train_seed
    from sb3_genrl.curves import MONITOR_FILE, read_monitor
    from sb3_genrl.generative import make_generator

    data = make_demonstrations("fetch-reach", 4, tmp_path / "demos", seed=3, n_threads=1, progress_bar=False)
    generator = tmp_path / "vae.pt"
    make_generator("VAE-FETCH", horizon=50, action_dim=4, device="cpu").save(str(generator))
    args = argparse.Namespace(
        episodes=64, eval_every=32, eval_states=2, no_demonstrations=False, dataset=str(data), work=str(tmp_path / "w")
    )
    row: dict = {"seed": 0}
    monkeypatch.setattr(fetch_seed.shutil, "rmtree", lambda *args, **kwargs: None)  # as if stopped before the end
    train_seed("fetch-reach", str(generator), 0, args, row, lambda: None)
    monkeypatch.undo()
    folder = tmp_path / "w" / "seed_0"
    assert len(read_monitor(folder / MONITOR_FILE)["return"]) == 64 and (folder / "checkpoint").is_dir()
    # the seed resumes from its checkpoint at episode 32 and plays the last 32 episodes again
    train_seed("fetch-reach", str(generator), 0, args, row, lambda: None)
    assert row["resumed_at_episodes"] == [32]
    assert len(read_monitor(folder / MONITOR_FILE)["return"]) == 64


def test_the_quickstart_refuses_fetch_demonstrations_of_another_recipe(tmp_path, cli):
    from sb3_genrl.envs.demonstrations import make_demonstrations

    out = tmp_path / "quickstart"
    data = make_demonstrations("fetch-reach", 4, out / "demonstrations", seed=0, n_threads=1, progress_bar=False)
    metadata_file = data / "data" / "metadata.json"
    metadata = json.loads(metadata_file.read_text())
    assert metadata["genrl"]["aim_margin"] == 0.05
    metadata["genrl"]["aim_margin"] = 0.02  # as made by a version whose Reach aims spread over a narrower region
    metadata_file.write_text(json.dumps(metadata))
    code, _, err = cli("quickstart", "--task", "fetch-reach", "--out", out, "--demo-episodes", 4, "--no-progress-bar")
    assert code == 2 and "aim_margin 0.02 (recorded) vs 0.05 (this run)" in err, err
    assert sorted(path.name for path in out.iterdir()) == ["demonstrations"]  # nothing made before the refusal
