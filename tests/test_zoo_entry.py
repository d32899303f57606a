"""rl-zoo3's entry point, ``python -m sb3_genrl.zoo`` (:mod:`sb3_genrl.zoo.__main__`): rl-zoo3's own parsing of its
options, a user's mistakes answered in one line before any work, the generator cache checked before it is used, and
``build-generator``. A cache that cannot be made (a folder under a file) stands in for a missing generator wherever a
test must not build the quickstart's, so a check that came after the cache would fail on the cache instead."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import gymnasium as gym
import pytest
import yaml

pytest.importorskip("rl_zoo3")

from sb3_genrl import GenRL  # noqa: E402
from sb3_genrl.hyperparams import hyperparams_file  # noqa: E402
from sb3_genrl.utils import atomic_write_json  # noqa: E402
from sb3_genrl.zoo import generators  # noqa: E402
from sb3_genrl.zoo.__main__ import main  # noqa: E402
from sb3_genrl.zoo.experiment import WRAPPER, resolved_wrapper  # noqa: E402
from sb3_genrl.zoo.wrapper import latent_action  # noqa: E402

ENV_ID = "GenRL/Hockey-v0"


@pytest.fixture
def zoo(capsys: pytest.CaptureFixture[str]):
    """Run ``python -m sb3_genrl.zoo ARGS...`` in-process: the exit status, stdout and stderr (argparse's exits
    included)."""

    def run(*argv: object) -> tuple[int, str, str]:
        try:
            code = main([str(arg) for arg in argv])
        except SystemExit as exit_:
            code = exit_.code
        captured = capsys.readouterr()
        return code, captured.out, captured.err

    return run


@pytest.fixture
def no_cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """A generator cache that cannot be made (its folder would lie under a file)."""
    (tmp_path / "a-file").write_text("")
    monkeypatch.setenv(generators.CACHE_VARIABLE, str(tmp_path / "a-file" / "cache"))
    return tmp_path / "a-file"


def one_line_error(code: int, err: str) -> str:
    """The one line of a refused command (exit status 2, no traceback)."""
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def with_generator(generator: object, key: str = "generator") -> list[str]:
    return ["-params", f"env_wrapper:[{{'{WRAPPER}': {{'{key}': '{generator}'}}}}]"]


def settings_file(path: Path, **changes: object) -> Path:
    """The package's hockey entry with ``changes``, as a settings file of the user's own."""
    entry = yaml.safe_load(hyperparams_file("genrl").read_text())[ENV_ID] | changes
    path.write_text(yaml.safe_dump({ENV_ID: entry}))
    return path


@pytest.mark.parametrize(
    "spelling",
    [
        ["--conf-file", "{}"],
        ["--conf-file={}"],
        ["-conf", "{}"],
        ["-conf={}"],
        ["--conf", "{}"],  # argparse's abbreviation of --conf-file
        ["--conf-f={}"],
    ],
)
def test_every_spelling_of_the_settings_option_is_honoured(spelling, zoo, no_cache, tmp_path):
    mine = settings_file(tmp_path / "mine.yml", not_a_setting=1)
    code, _, err = zoo(
        "train", "--algo", "genrl", "--env", ENV_ID, *(part.format(mine) for part in spelling), "-f", tmp_path / "logs"
    )
    line = one_line_error(code, err)
    assert f"the settings of {mine}" in line and "'not_a_setting' is not a GenRL setting" in line
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize("algo", [["--algo", "genrl"], ["--algo=genrl"], ["--al", "genrl"]])
def test_every_spelling_of_the_algo_option_reads_genrls_settings_file(algo, zoo, no_cache, tmp_path):
    code, _, err = zoo("train", *algo, "--env", ENV_ID, "-f", tmp_path / "logs")
    line = one_line_error(code, err)  # the package's entry passed its checks; the cache is the first thing missing
    assert f"the generator cache ${generators.CACHE_VARIABLE}: {str(no_cache / 'cache' / 'generators' / 'hockey')!r}" in line


def test_user_mistakes_are_one_line_before_any_generator_is_made(zoo, no_cache, tmp_path, monkeypatch):
    logs = tmp_path / "logs"
    mistakes = {
        ("--env", "GenRL/Hocky-v0"): "GenRL/Hocky-v0 not found in gym registry, you maybe meant GenRL/Hockey-v0?",
        ("--env", "CartPole-v1"): f"Hyperparameters not found for genrl-CartPole-v1 in {hyperparams_file('genrl')}",
        ("--env", ENV_ID, "-params", "not_a_setting:1"): "'not_a_setting' is not a GenRL setting",
        ("--env", ENV_ID, "-conf", settings_file(tmp_path / "s.yml", n_steps="sixteen")): (
            "n_steps must be an integer of at least 1, got 'sixteen'"
        ),
        ("--env", ENV_ID, *with_generator("vae.pt", key="generatr")): (
            f"env_wrapper {WRAPPER}: 'generatr' is not among its arguments (generator, generator_sha256, latent_clip)"
        ),
        ("--env", ENV_ID, *with_generator(tmp_path / "none.pt")): f"no generator file {str(tmp_path / 'none.pt')!r}",
        ("--env", ENV_ID, "-i", tmp_path / "model.pt"): "The trained_agent must be a valid path to a .zip file",
        (
            "--env",
            ENV_ID,
            "-n",
            "-5",
        ): "-n/--n-timesteps must be a positive integer (left out: the entry's n_timesteps), got -5",
        ("--env", ENV_ID, "-n", "0"): "-n/--n-timesteps must be a positive integer",
        ("--env", ENV_ID, "-params", "n_steps:sixteen"): "-params: a value is not a Python literal (name 'sixteen' is not",
    }
    for arguments, message in mistakes.items():
        line = one_line_error(*zoo("train", "--algo", "genrl", *arguments, "-f", logs)[::2])
        assert line.startswith("python -m sb3_genrl.zoo train: error: ") and message in line, (arguments, line)
    for script in ("enjoy", "record_video"):  # rl-zoo3's own checks, asserts
        line = one_line_error(*zoo(script, "--algo", "genrl", "--env", ENV_ID, "-f", logs)[::2])
        assert line == f"python -m sb3_genrl.zoo {script}: error: The {logs / 'genrl'} folder was not found"
    monkeypatch.delitem(gym.registry, "FetchPush-v4", raising=False)  # as without Gymnasium-Robotics
    line = one_line_error(*zoo("train", "--algo", "genrl", "--env", "FetchPush-v4", "-f", logs)[::2])
    assert 'FetchPush-v4 is not available: the Fetch tasks need Gymnasium-Robotics: pip install "sb3-genrl[robotics]"' in line
    assert sorted(path.name for path in tmp_path.iterdir()) == [no_cache.name, "s.yml"]  # no logs, nothing made


def test_a_cache_that_cannot_be_written_is_one_line_naming_the_variable(zoo, monkeypatch, tmp_path):
    if os.geteuid() == 0:  # root ignores permissions: a read-only file system
        cache = Path("/sys/sb3-genrl-cache")
    else:
        (tmp_path / "read-only").mkdir(mode=0o555)
        cache = tmp_path / "read-only" / "cache"
    monkeypatch.setenv(generators.CACHE_VARIABLE, str(cache))
    line = one_line_error(*zoo("train", "--algo", "genrl", "--env", ENV_ID, "-f", tmp_path / "logs")[::2])
    assert f"{str(cache / 'generators' / 'hockey')!r} cannot be written" in line
    assert f"set {generators.CACHE_VARIABLE} to a folder that can be written" in line
    assert not (tmp_path / "logs").exists()


def cached(hockey_generator: str, **recorded: object) -> Path:
    """``hockey_generator`` in the cache, with ``stage.json`` recording the cache's settings changed by ``recorded``."""
    path = generators.default_generator(ENV_ID)
    path.parent.mkdir(parents=True)
    shutil.copy(hockey_generator, path)
    atomic_write_json(path.parent / "stage.json", generators.generator_settings(ENV_ID) | recorded)
    return path


def test_a_stale_generator_cache_is_refused_even_with_its_generator(zoo, hockey_generator, monkeypatch, tmp_path):
    monkeypatch.setenv(generators.CACHE_VARIABLE, str(tmp_path / "cache"))
    path = cached(hockey_generator, epochs=2, version="0.0.1")
    arguments = ("train", "--algo", "genrl", "--env", ENV_ID, "-n", 16, "--eval-freq", -1, "--device", "cpu")
    line = one_line_error(*zoo(*arguments, "-f", tmp_path / "logs")[::2])
    assert 'epochs 2 (recorded) vs 300 (this run), version "0.0.1" (recorded)' in line
    assert f"remove {path.parent} and run `python -m sb3_genrl.zoo build-generator --env {ENV_ID}`" in line
    with pytest.raises(ValueError, match="made by another version or with other settings"):
        latent_action(gym.make(ENV_ID))  # enjoy's and a user's own envs
    (path.parent / "stage.json").unlink()  # a generator of unknown settings
    line = one_line_error(*zoo(*arguments, "-f", tmp_path / "logs")[::2])
    assert "no recorded settings" in line
    assert not (tmp_path / "logs").exists() and path.is_file()  # nothing rebuilt or removed


def test_continuing_a_model_with_another_generator_is_refused(zoo, hockey_generator, tmp_path):
    from stable_baselines3.common.env_util import make_vec_env

    from sb3_genrl.generative import make_generator
    from sb3_genrl.genrl.generator_files import generator_digest
    from sb3_genrl.zoo.wrapper import load_generator

    other = tmp_path / "other.pt"
    make_generator("VAE2", horizon=69, action_dim=7, device="cpu").save(str(other))  # the same shape, another beta
    assert generator_digest(load_generator(other)) != generator_digest(load_generator(Path(hockey_generator)))
    env = make_vec_env(ENV_ID, wrapper_class=latent_action, wrapper_kwargs={"generator": hockey_generator})
    GenRL("MlpPolicy", env, n_steps=16, batch_size=16, device="cpu").save(tmp_path / "model.zip")
    line = one_line_error(
        *zoo(
            "train",
            "--algo",
            "genrl",
            "--env",
            ENV_ID,
            "-i",
            tmp_path / "model.zip",
            "-n",
            16,
            "--eval-freq",
            -1,
            "--device",
            "cpu",
            "-f",
            tmp_path / "logs",
            *with_generator(other),
        )[::2]
    )
    assert f"-i {tmp_path / 'model.zip'} was trained with another generator" in line and str(other) in line
    assert not (tmp_path / "logs").exists()
    from sb3_genrl.zoo.experiment import check_trained_agent  # the same check passes the generator it was trained with

    check_trained_agent(str(tmp_path / "model.zip"), resolved_wrapper([{WRAPPER: {"generator": hockey_generator}}], ENV_ID))


def test_build_generator_says_what_it_makes_then_makes_it_once(zoo, monkeypatch, tmp_path):
    monkeypatch.setenv(generators.CACHE_VARIABLE, str(tmp_path / "cache"))
    monkeypatch.setattr(generators, "DEMO_EPISODES", 8)  # the quickstart's sizes, made small
    monkeypatch.setattr(generators, "GENERATOR_EPOCHS", 1)
    monkeypatch.setattr(generators, "GENERATOR_EVAL_EVERY", 1)
    code, out, err = zoo("build-generator", "--env", ENV_ID, "--device", "cpu")
    assert code == 0, err
    announced, demonstrations, training, done = out.strip().splitlines()
    folder = tmp_path / "cache" / "generators" / "hockey"
    assert announced.startswith(
        f"{ENV_ID}: making the task's generator into {folder}, once (later runs reuse it): 8 demonstrations, then the "
        "beta-VAE VAE1 trained for 1 epochs; a few minutes on a CPU"
    )
    assert demonstrations.startswith(f"{ENV_ID}: 1/2 making 8 demonstrations")
    assert training.startswith(f"{ENV_ID}: 2/2 training the generator VAE1 for 1 epochs")
    assert done == f"{ENV_ID}: the generator {folder / 'vae.pt'} is made; train --algo genrl --env {ENV_ID} uses it"
    generators.check_cache(ENV_ID)
    made = (folder / "vae.pt").stat().st_mtime_ns
    assert zoo("build-generator", "--env", ENV_ID)[:2] == (0, f"{ENV_ID}: the generator {folder / 'vae.pt'} is made already\n")
    assert (folder / "vae.pt").stat().st_mtime_ns == made
    line = one_line_error(*zoo("build-generator", "--env", "GenRL/Hocky-v0")[::2])
    assert "unknown task 'GenRL/Hocky-v0'" in line
