"""Play each task's scripted expert, render it offscreen and write a short Markdown report with images.

Task-level workflow code: it reads the task registry (:data:`sb3_genrl.envs.TASKS`) inside its functions.
"""

from __future__ import annotations

import errno
import functools
import os
import warnings
from pathlib import Path

import imageio.v3 as iio
import mujoco
import numpy as np

from sb3_genrl.checks import check_not_in_a_dataset, check_output_dir, check_positive_int, check_seed
from sb3_genrl.envs import arm_tasks, get_task
from sb3_genrl.utils import atomic_path, atomic_write_bytes, atomic_write_text


@functools.cache
def _rendering_failure() -> str | None:
    """Why MuJoCo cannot render offscreen in this process (its error), or ``None`` when it can: a 16 x 16 renderer of
    an empty model, made and closed (once per process)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # GLFW warns before it fails without a display; the error says why
            renderer = mujoco.Renderer(mujoco.MjModel.from_xml_string("<mujoco/>"), 16, 16)
    except Exception as error:  # mujoco.FatalError, or the OpenGL library's own error
        return f"{type(error).__name__}: {error}"
    renderer.close()
    return None


def check_rendering(skip: str = "") -> None:
    """Check, before any work, that MuJoCo can render offscreen here: without a display its default OpenGL backend
    (GLFW) fails only at the first frame, after every stage before it.

    :param skip: how the caller's user leaves the rendering out, added to the message (e.g. ``"--no-video"``)
    :raises ValueError: naming ``MUJOCO_GL``'s value and the backends that need no display
    """
    failure = _rendering_failure()
    if failure is None:
        return
    backend = os.environ.get("MUJOCO_GL")
    backend = f"MUJOCO_GL={backend}" if backend else "MUJOCO_GL unset: GLFW, which needs a display"
    raise ValueError(
        f"rendering: MuJoCo cannot make an OpenGL context here ({backend}; {failure}); on a machine without a display "
        "set MUJOCO_GL=egl (or osmesa) before the command" + (f", or leave the rendering out ({skip})" if skip else "")
    )


def frame_strip(frames: list[np.ndarray], n: int = 6) -> np.ndarray:
    """``n`` frames evenly spaced over the episode, side by side."""
    picks = np.linspace(0, len(frames) - 1, n).round().astype(int)
    return np.concatenate([frames[i] for i in picks], axis=1)


def save_animation(frames: list[np.ndarray], path: str | Path, fps: int = 25) -> Path:
    """Write frames as a GIF or MP4 (by the file's suffix), atomically. An MP4 is read back before it takes its name:
    one that does not hold every frame (ffmpeg prints its failures, a full disk among them, and exits without an
    error reaching Python) raises ``OSError`` naming ``path``, and nothing is left there."""
    path = Path(path)
    if path.suffix.lower() == ".gif":  # made in memory: a failed write is the file's own, naming it
        atomic_write_bytes(path, iio.imwrite("<bytes>", np.stack(frames), extension=".gif", duration=1000 / fps, loop=0))
        return path
    with atomic_path(path) as tmp:  # the temporary name keeps the suffix, which picks the format
        iio.imwrite(tmp, np.stack(frames), fps=fps)
        _check_video_frames(tmp, len(frames), path)
    return path


def _check_video_frames(video: Path, expected: int, final: Path) -> None:
    """Refuse the MP4 ``video`` (to be renamed ``final``) unless it holds ``expected`` frames."""
    import imageio_ffmpeg  # imageio's FFmpeg plugin, needed for MP4 only (sb3_genrl.video.check_mp4_writer)

    try:
        written = imageio_ffmpeg.count_frames_and_secs(str(video))[0]
    except RuntimeError:  # ffmpeg cannot read it: the file ends early
        written = 0
    if written != expected:
        raise OSError(
            errno.EIO, f"ffmpeg wrote {written} of {expected} frames (see its messages above; is the disk full?)", str(final)
        )


def save_image(image: np.ndarray, path: str | Path) -> Path:
    """Write one image (format by the file's suffix) atomically."""
    return atomic_write_bytes(path, iio.imwrite("<bytes>", image, extension=Path(path).suffix))


def play_scripted(
    out_dir: str | Path, *, tasks: tuple[str, ...] | None = None, seed: int = 0, width: int = 320, height: int = 240
) -> Path:
    """Play one base motion of each task's scripted expert, save frame strips and GIFs, and write ``report.md``.

    The motion is the expert's (:attr:`TaskSpec.sample_expert <sb3_genrl.envs.spec.TaskSpec>`, unperturbed) drawn
    with ``np.random.default_rng(seed)``; its goal, marked in red, is the point it reaches, as in the demonstrations.

    :param out_dir: output folder (created)
    :param tasks: task names from :func:`sb3_genrl.envs.arm_tasks` (default: all of them)
    :param seed: seed of the motions
    :param width: frame width (pixels)
    :param height: frame height (pixels)
    :return: the report's path
    """
    specs = [get_task(name) for name in dict.fromkeys(tasks or arm_tasks())]  # a task named twice is shown once
    others = [spec.name for spec in specs if spec.name not in arm_tasks()]
    if others:
        raise ValueError(f"the scripted motions are shown for the tasks on the package's arm {arm_tasks()}; got {others}")
    check_seed(seed)
    check_positive_int(width, "width")
    check_positive_int(height, "height")
    out = check_output_dir(out_dir)
    check_not_in_a_dataset(out)
    check_rendering()
    out.mkdir(parents=True, exist_ok=True)
    lines = [
        "# Scripted motions of the GenRL tasks",
        "",
        "One base motion of each task's scripted expert played on its MuJoCo task (offscreen rendering); the red "
        "goal marks the point it reaches.",
        "",
    ]
    for spec in specs:
        env = spec.make_env(render_mode="rgb_array", width=width, height=height)
        trajectory = spec.sample_expert(np.random.default_rng(seed))
        _, info = env.play_trajectory(trajectory, 0.5 * (spec.goal_low + spec.goal_high))
        goal = np.asarray(info["reached"], dtype=np.float64)
        frames = env.episode_frames(trajectory, goal, every=2)
        save_image(frame_strip(frames), out / f"{spec.name}_strip.png")
        save_animation(frames, out / f"{spec.name}.gif", fps=12)
        env.close()
        lines += [
            f"## {spec.name}",
            "",
            f"![{spec.name}]({spec.name}.gif)",
            "",
            f"![{spec.name} frames]({spec.name}_strip.png)",
            "",
            f"- reached: ({goal[0]:.2f}, {goal[1]:.2f}) m; in the goal region: "
            f"{'yes' if spec.in_goal_region(goal[None])[0] else 'no'}",
            "",
        ]
        if "table_contacts" in info:
            lines += [f"- table contacts: {info['table_contacts']}", ""]
    report = out / "report.md"
    atomic_write_text(report, "\n".join(lines))
    return report
