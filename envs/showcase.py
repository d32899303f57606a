"""Play the scripted hit and throw, render them offscreen and write a short Markdown report with images."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
from sb3_genrl.envs.basketball import BasketballEnv
from sb3_genrl.envs.hockey import HockeyEnv
from sb3_genrl.envs.scripted import scripted_hit, scripted_throw


def frame_strip(frames: list[np.ndarray], n: int = 6) -> np.ndarray:
    """``n`` frames evenly spaced over the episode, side by side."""
    picks = np.linspace(0, len(frames) - 1, n).round().astype(int)
    return np.concatenate([frames[i] for i in picks], axis=1)


def save_animation(frames: list[np.ndarray], path: str | Path, fps: int = 25) -> Path:
    """Write frames as a GIF or MP4 (by the file's suffix)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        iio.imwrite(path, np.stack(frames), duration=1000 / fps, loop=0)
    else:
        iio.imwrite(path, np.stack(frames), fps=fps)
    return path


def play_scripted(out_dir: str | Path, *, width: int = 320, height: int = 240) -> Path:
    """Play a scripted hockey hit and basketball throw, save frame strips and GIFs, and write ``report.md``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cases = [
        ("hockey", HockeyEnv(render_mode="rgb_array", width=width, height=height), scripted_hit(strength=1.0, direction=0.2),
         np.array([0.9, -0.1])),
        ("basketball", BasketballEnv(render_mode="rgb_array", width=width, height=height), scripted_throw(yaw=0.3),
         np.array([3.3, 1.0])),
    ]
    lines = ["# Scripted motions on the GenRL tasks", "",
             "A hand-written hit and throw played on the MuJoCo tasks (offscreen rendering).", ""]
    for name, env, trajectory, goal in cases:
        reward, info = env.play_trajectory(trajectory, goal)
        frames = env.episode_frames(trajectory, goal, every=2)
        iio.imwrite(out / f"{name}_strip.png", frame_strip(frames))
        save_animation(frames, out / f"{name}.gif", fps=12)
        env.close()
        reached = ", ".join(f"{v:.2f}" for v in info["reached"])
        lines += [f"## {name}", "", f"![{name}]({name}.gif)", "", f"![{name} frames]({name}_strip.png)", "",
                  f"- goal: ({goal[0]:.2f}, {goal[1]:.2f}) m; reached: ({reached}) m; reward: {reward:.3f}", ""]
        if "table_contacts" in info:
            lines.append(f"- table contacts: {info['table_contacts']}")
            lines.append("")
    report = out / "report.md"
    report.write_text("\n".join(lines))
    return report
