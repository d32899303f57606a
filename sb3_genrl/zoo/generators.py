"""The generator of a task's rl-zoo3 runs when its settings name none: the quickstart's, made once into a cache.

``hyperparams/genrl.yml`` gives each task the env wrapper ``sb3_genrl.zoo.latent_action`` without a generator file, so
that ``python -m sb3_genrl.zoo train --algo genrl --env GenRL/Hockey-v0`` runs on a fresh clone: the task's generator
is then the one ``genrl quickstart`` trains (its preset, epochs and seed, from
:data:`~sb3_genrl.study.quickstart.DEMO_EPISODES` demonstrations: hockey's quickstart makes fewer, but the committed
rl-zoo3 studies were made with these), made by the same stages into ``$SB3_GENRL_CACHE/generators/<task>/vae.pt``
(default ``~/.cache/sb3-genrl``) the first time a run needs it (or ahead of time: ``python -m sb3_genrl.zoo
build-generator --env GenRL/Hockey-v0``), with the stages' progress shown, and reused after. The folder records the
settings that made it (``stage.json``, the package's version included); a folder made with other settings, or with no
record, is refused (:func:`check_cache`), never used or rebuilt silently.
"""

from __future__ import annotations

import os
import pathlib
from collections.abc import Callable

import sb3_genrl
from sb3_genrl.checks import check_output_dir
from sb3_genrl.envs import get_task
from sb3_genrl.envs.demonstrations import make_demonstrations
from sb3_genrl.generative import train_generator
from sb3_genrl.run.stages import STAGE_FILE, check_and_record, read_settings, settings_conflicts
from sb3_genrl.study.quickstart import DEMO_EPISODES, GENERATOR_EPOCHS, GENERATOR_EVAL_EVERY, quickstart_preset
from sb3_genrl.utils import folder_lock

CACHE_VARIABLE = "SB3_GENRL_CACHE"
SEED = 0  # the quickstart's default seed
# What making a generator takes, said before it starts: the quickstart's two stages on an idle 2-core CPU
# (docs/results.md, "The quickstart": 1.5 to 3 minutes by task); a busy machine takes longer.
BUILD_TIME = "a few minutes on a CPU (about 2 to 3 on an idle 2-core machine, longer on a busy one)"


def cache_folder() -> pathlib.Path:
    """``$SB3_GENRL_CACHE``, else ``~/.cache/sb3-genrl``."""
    return pathlib.Path(os.environ.get(CACHE_VARIABLE) or pathlib.Path.home() / ".cache" / "sb3-genrl").expanduser()


def default_generator(task: str) -> pathlib.Path:
    """Where the task's quickstart generator is cached (it may not exist yet)."""
    return cache_folder() / "generators" / get_task(task).name / "vae.pt"


def default_demonstrations(task: str) -> pathlib.Path:
    """The demonstrations the task's cached generator (:func:`default_generator`) was trained on."""
    return default_generator(task).parent / "demonstrations"


def build_command(task: str) -> str:
    """The command that makes the task's cached generator ahead of time."""
    return f"python -m sb3_genrl.zoo build-generator --env {get_task(task).env_id}"


def generator_settings(task: str) -> dict[str, object]:
    """What the cached generator of ``task`` is made with (recorded beside it)."""
    return {
        "task": get_task(task).name,
        "demo_episodes": DEMO_EPISODES,
        "preset": quickstart_preset(task),
        "epochs": GENERATOR_EPOCHS,
        "eval_every": GENERATOR_EVAL_EVERY,
        "seed": SEED,
        "version": sb3_genrl.__version__,
    }


def check_cache(task: str) -> None:
    """Refuse the task's cache folder when it holds a generator or a started build of other settings than this
    version makes (its ``stage.json``), or a generator without a record; nothing is written.

    :param task: a task name or Gymnasium id
    :raises ValueError: naming the folder, the differing settings and how to make the generator again
    """
    path = default_generator(task)
    folder = path.parent
    conflicts = settings_conflicts(
        folder, read_settings(folder / STAGE_FILE), generator_settings(task), output_exists=path.exists()
    )
    if conflicts:
        raise ValueError(
            f"the cached generator of {'; '.join(conflicts)}: it was made by another version or with other settings, "
            f"and is not used; remove {folder} and run `{build_command(task)}` to make it again, or give a generator "
            "file as the wrapper's `generator`"
        )


def check_cache_writable(task: str) -> None:
    """Refuse a cache folder that cannot be written (before any generator is made into it).

    :param task: a task name or Gymnasium id
    :raises PermissionError: naming the folder and the variable that moves the cache
    """
    folder = default_generator(task).parent
    try:
        check_output_dir(folder, f"the generator cache ${CACHE_VARIABLE}:")
    except ValueError as error:
        raise PermissionError(
            f"{error}; set {CACHE_VARIABLE} to a folder that can be written, or give a generator file as the "
            "wrapper's `generator`"
        ) from None


def build_default_generator(
    task: str, *, device: str = "auto", progress_bar: bool = True, log: Callable[[str], None] = print
) -> pathlib.Path:
    """Make the task's quickstart generator into the cache unless it is there: demonstrations, then the beta-VAE.
    A cache of other settings (:func:`check_cache`) or one that cannot be written is refused before any work.

    :param task: a task name or Gymnasium id
    :param device: torch device of the generator's training
    :param progress_bar: show the stages' progress bars
    :param log: called with what is about to be made (and how long it takes), then a line before each stage
    :return: the generator's file
    """
    path = default_generator(task)
    settings = generator_settings(task)
    folder = path.parent
    check_cache(task)
    if path.exists():
        return path
    check_cache_writable(task)
    env_id = get_task(task).env_id
    log(
        f"{env_id}: making the task's generator into {folder}, once (later runs reuse it): {DEMO_EPISODES} "
        f"demonstrations, then the beta-VAE {settings['preset']} trained for {GENERATOR_EPOCHS} epochs; "
        f"{BUILD_TIME}. `{build_command(task)}` makes it ahead of time"
    )
    with folder_lock(folder):
        check_and_record(folder / STAGE_FILE, settings, output_exists=path.exists(), folder=folder)
        if path.exists():  # made by another process while this one waited
            return path
        dataset = default_demonstrations(task)
        if not (dataset.is_dir() and any(dataset.iterdir())):
            log(f"{env_id}: 1/2 making {DEMO_EPISODES} demonstrations -> {dataset}")
            make_demonstrations(task, DEMO_EPISODES, dataset, seed=SEED, progress_bar=progress_bar)
        log(f"{env_id}: 2/2 training the generator {settings['preset']} for {GENERATOR_EPOCHS} epochs -> {path}")
        train_generator(
            dataset,
            preset=str(settings["preset"]),
            epochs=GENERATOR_EPOCHS,
            eval_every=GENERATOR_EVAL_EVERY,
            seed=SEED,
            out=path,
            progress_bar=progress_bar,
            device=device,
        )
    return path
