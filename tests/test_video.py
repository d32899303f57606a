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
