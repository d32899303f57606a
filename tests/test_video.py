"""Videos (sb3_genrl.showcase.save_animation, behind ``genrl video``): an MP4 appears whole at its path or not at all."""

from __future__ import annotations

import errno

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np
import pytest

from sb3_genrl.showcase import save_animation


def test_a_video_that_ffmpeg_could_not_finish_is_not_left_at_its_path(tmp_path, monkeypatch):
    frames = [np.full((48, 64, 3), 20 * i, np.uint8) for i in range(10)]
    video = save_animation(frames, tmp_path / "v.mp4", fps=10)
    assert imageio_ffmpeg.count_frames_and_secs(str(video))[0] == 10
    whole = video.read_bytes()
    imwrite = iio.imwrite

    def cut_short(path, image, **kwargs):  # as ffmpeg on a full disk: it prints the error, Python sees none
        imwrite(path, image, **kwargs)
        with open(path, "r+b") as file:
            file.truncate(len(whole) // 2)

    monkeypatch.setattr(iio, "imwrite", cut_short)
    for path in (tmp_path / "new.mp4", video):  # a new video, and one that replaces the whole one
        with pytest.raises(OSError, match="ffmpeg wrote 0 of 10 frames") as error:
            save_animation(frames, path, fps=10)
        assert error.value.errno == errno.EIO and error.value.filename == str(path)
    assert [path.name for path in tmp_path.iterdir()] == ["v.mp4"] and video.read_bytes() == whole


@pytest.fixture
def no_renderer(monkeypatch):
    """MuJoCo's renderer failing as it does without a display and MUJOCO_GL unset (GLFW), for this test only."""
    import mujoco

    from sb3_genrl import showcase

    def fail(*args, **kwargs):
        raise mujoco.FatalError("an OpenGL platform library has not been loaded into this process")

    showcase._rendering_failure.cache_clear()
    monkeypatch.setattr(mujoco, "Renderer", fail)
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    yield
    showcase._rendering_failure.cache_clear()


def test_rendering_is_checked_before_any_work(no_renderer, tmp_path):
    from sb3_genrl.showcase import play_scripted
    from sb3_genrl.video import record_video

    message = r"MUJOCO_GL unset: GLFW, which needs a display; FatalError: an OpenGL .* set MUJOCO_GL=egl"
    with pytest.raises(ValueError, match=message):
        play_scripted(tmp_path / "play", tasks=("hockey",))
    generator = tmp_path / "vae.pt"
    generator.write_bytes(b"")  # never read: the check comes first
    with pytest.raises(ValueError, match=message):
        record_video("hockey", tmp_path / "v.gif", generator=generator)
    assert sorted(path.name for path in tmp_path.iterdir()) == ["vae.pt"]


def test_the_quickstart_checks_rendering_only_when_it_still_has_a_video_to_make(no_renderer, tmp_path, monkeypatch):
    from sb3_genrl.study import quickstart as quickstart_module

    class Stages(Exception):
        pass

    def stages(*args, **kwargs):
        raise Stages

    monkeypatch.setattr(quickstart_module, "_run_stages", stages)
    monkeypatch.setattr(quickstart_module, "refuse_conflicts", lambda *args: None)  # the empty files below
    with pytest.raises(ValueError, match=r"leave the rendering out \(genrl quickstart --no-video"):
        quickstart_module.quickstart(tmp_path / "a", task="hockey")
    assert not (tmp_path / "a").exists()
    with pytest.raises(Stages):  # no video: no check
        quickstart_module.quickstart(tmp_path / "b", task="hockey", video=False)
    (tmp_path / "c").mkdir()
    for name in ("policy.gif", "policy_strip.png"):  # the video already made: a rerun renders nothing
        (tmp_path / "c" / name).write_bytes(b"")
    with pytest.raises(Stages):
        quickstart_module.quickstart(tmp_path / "c", task="hockey")


def test_genrl_quickstart_without_a_display_stops_before_its_first_stage(tmp_path):
    """The real failure: GLFW with no display to open (the variables removed), through the command line."""
    import os
    import subprocess
    import sys

    env = {key: value for key, value in os.environ.items() if key not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["MUJOCO_GL"] = "glfw"
    command = [sys.executable, "-m", "sb3_genrl.cli", "quickstart", "--out", str(tmp_path / "q")]
    result = subprocess.run(command, env=env, capture_output=True, text=True)
    assert result.returncode == 2, result.stderr
    assert "MUJOCO_GL=glfw" in result.stderr and "set MUJOCO_GL=egl" in result.stderr
    assert "--no-video" in result.stderr and not (tmp_path / "q").exists()


def test_a_video_of_an_unfinished_run_names_what_is_missing(tmp_path, hockey_generator):
    from sb3_genrl.video import record_video

    run = tmp_path / "run"
    run.mkdir()
    (run / "run_record.json").write_text("{}")  # a run claimed, not finished
    with pytest.raises(ValueError, match=r"policy: '.*run' holds no genrl_policy.zip; .* once its run has finished"):
        record_video("hockey", tmp_path / "v.gif", policy=run)
    assert not (tmp_path / "v.gif").exists()


def test_a_task_named_twice_is_played_once(tmp_path):
    from sb3_genrl.showcase import play_scripted

    report = play_scripted(tmp_path / "play", tasks=("hockey", "hockey"), width=32, height=24)
    assert report.read_text().count("## hockey") == 1


def test_play_and_the_quickstart_refuse_a_demonstration_datasets_folder(tmp_path):
    from sb3_genrl.showcase import play_scripted
    from sb3_genrl.study.quickstart import quickstart

    dataset = tmp_path / "demos"
    (dataset / "data").mkdir(parents=True)
    (dataset / "data" / "metadata.json").write_text("{}")
    for out in (dataset, dataset / "inside"):
        with pytest.raises(ValueError, match="demonstration dataset.*its files would join the dataset's own"):
            play_scripted(out, tasks=("hockey",))
        with pytest.raises(ValueError, match="demonstration dataset.*its files would join the dataset's own"):
            quickstart(out, task="hockey", video=False)
    assert sorted(path.name for path in dataset.rglob("*")) == ["data", "metadata.json"]
