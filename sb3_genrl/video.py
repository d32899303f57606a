"""Videos of a trained GenRL policy or of a generator's random trajectories, rendered offscreen.

Task-level workflow code: it reads the task registry (:data:`sb3_genrl.envs.TASKS`) inside its function.
"""

from __future__ import annotations

import json
import os
import pathlib

import numpy as np

from sb3_genrl.checks import check_input_path, check_output_file, check_positive_int, check_seed
from sb3_genrl.envs import get_task
from sb3_genrl.generative import load
from sb3_genrl.run.loading import load_policy
from sb3_genrl.showcase import check_rendering, frame_strip, save_animation, save_image

VIDEO_SUFFIXES = (".mp4", ".gif")
REAL_TIME_FPS = 25  # the arm tasks' control steps per second (20 physics steps of 2 ms): a frame each plays in real time


def check_mp4_writer(out: str | os.PathLike) -> None:
    """For an ``.mp4`` output, check that imageio's FFmpeg plugin (the package ``imageio-ffmpeg``) is there.

    Without it imageio would try another writer and fail after all the rendering with an unrelated message.

    :raises ValueError: naming the missing package and the alternatives
    """
    if pathlib.Path(out).suffix.lower() != ".mp4":
        return
    try:
        import imageio_ffmpeg  # MP4 only: without it a GIF is still written and an MP4 refused here, as one error

        imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as error:
        raise ValueError(
            f"out: writing {str(out)!r} needs imageio-ffmpeg, a dependency of sb3-genrl ({error}); "
            "install it (pip install imageio-ffmpeg) or write a .gif"
        ) from None


def _why_no_policy(folder: pathlib.Path) -> str:
    """Why a run folder holds no GenRL model: another algorithm's run, or a GenRL run not finished."""
    try:
        algorithm = json.loads((folder / "run_record.json").read_text()).get("algorithm")
    except (OSError, ValueError, AttributeError):
        algorithm = None
    if algorithm not in (None, "genrl"):
        return f"it is a {algorithm} run, not a GenRL one (genrl video films GenRL policies and generators)"
    return "a GenRL run folder has one once its run has finished (rerun its genrl train-policy command to finish it)"


def record_video(
    task: str,
    out: str | os.PathLike,
    *,
    policy: str | os.PathLike | None = None,
    generator: str | os.PathLike | None = None,
    goals: int = 6,
    seed: int = 0,
    width: int = 480,
    height: int = 352,
    fps: int = REAL_TIME_FPS,
    every: int = 1,
    strip: bool = True,
    trust_policy: bool = False,
) -> dict:
    """Play ``goals`` episodes and write them one after the other as an MP4 or GIF (by ``out``'s suffix).

    With ``policy`` (a GenRL run folder or model zip) the policy picks each goal's latent action
    (deterministically); with ``generator`` (a generator file) the latent actions are random prior samples. The goal
    is marked in red. A strip of frames (``<out>_strip.png``) is written beside the video unless ``strip=False``.

    :param task: a task name from :data:`sb3_genrl.envs.TASKS`
    :param goals: episodes (goals) to show, drawn with ``seed`` (which also draws the random latent actions)
    :param every: a frame every ``every`` control steps (2 renders half the frames; with half the ``fps`` the video
        keeps its pace)
    :param trust_policy: load the policy zip with SB3's unpickling (see :func:`sb3_genrl.run.loading.load_policy`);
        by default nothing in it is unpickled
    :return: ``video``, ``strip`` paths and per-episode ``rewards``
    """
    spec = get_task(task)
    if (policy is None) == (generator is None):
        raise ValueError("give exactly one of policy= (a GenRL run) or generator= (a generator file)")
    for name, value in (("goals", goals), ("width", width), ("height", height), ("fps", fps), ("every", every)):
        check_positive_int(value, name)
    check_seed(seed)
    check_output_file(out, "out", suffixes=VIDEO_SUFFIXES)
    check_mp4_writer(out)
    check_input_path(policy if policy is not None else generator, "policy" if policy is not None else "generator")
    if policy is not None and pathlib.Path(policy).is_dir() and not (pathlib.Path(policy) / "genrl_policy.zip").is_file():
        raise ValueError(f"policy: {os.fspath(policy)!r} holds no genrl_policy.zip; {_why_no_policy(pathlib.Path(policy))}")
    check_rendering()
    env = spec.make_env(render_mode="rgb_array", width=width, height=height)
    rng = np.random.default_rng(seed)
    goal_list = np.array([env.sample_goal(rng) for _ in range(goals)])
    if policy is not None:
        path = pathlib.Path(policy)
        model = load_policy(path / "genrl_policy.zip" if path.is_dir() else path, env, trust=trust_policy)
        alphas, _ = model.predict(goal_list.astype(np.float32), deterministic=True)
        trajectories = model.generator.decode(alphas)
    else:
        model_generator = load(generator, device="cpu")
        if model_generator.horizon != env.horizon:
            raise ValueError(f"the generator's horizon {model_generator.horizon} is not the {task} task's {env.horizon}")
        trajectories = model_generator.decode(model_generator.sample_prior(goals, rng))
    rewards, _ = env.play_trajectories(trajectories, goal_list)
    frames: list[np.ndarray] = []
    firsts = []
    for trajectory, goal in zip(trajectories, goal_list, strict=True):
        episode = env.episode_frames(trajectory, goal, every=every)
        firsts.append(len(frames))
        frames += episode + [episode[-1]] * (fps // 2)  # hold the end for half a second
    env.close()
    video = save_animation(frames, out, fps=fps)
    result = {"video": str(video), "rewards": rewards.tolist()}
    if strip:
        strip_path = video.with_name(video.stem + "_strip.png")
        ends = [frames[i - 1] for i in [*firsts[1:], len(frames)]]
        save_image(frame_strip(ends, n=min(6, len(ends))), strip_path)
        result["strip"] = str(strip_path)
    return result
