"""The generator of a task's rl-zoo3 runs when its settings name none: the quickstart's, made once into a cache.

``hyperparams/genrl.yml`` gives each task the env wrapper ``sb3_genrl.zoo.latent_action`` without a generator file, so
that ``python -m sb3_genrl.zoo train --algo genrl --env GenRL/Hockey-v0`` runs on a fresh clone: the task's
generator is then the one ``genrl quickstart`` trains (its demonstrations, preset, epochs and seed), made by the same
stages into ``$SB3_GENRL_CACHE/generators/<task>/vae.pt`` (default ``~/.cache/sb3-genrl``) the first time a run needs
it, with the stages' progress shown, and reused after. The folder records the settings that made it
(``stage.json``) and refuses to be reused under others.
"""

from __future__ import annotations

import os
import pathlib
from collections.abc import Callable

from sb3_genrl.study.quickstart import DEMO_EPISODES, GENERATOR_EPOCHS, GENERATOR_EVAL_EVERY

CACHE_VARIABLE = "SB3_GENRL_CACHE"
SEED = 0  # the quickstart's default seed


def cache_folder() -> pathlib.Path:
    """``$SB3_GENRL_CACHE``, else ``~/.cache/sb3-genrl``."""
    return pathlib.Path(os.environ.get(CACHE_VARIABLE) or pathlib.Path.home() / ".cache" / "sb3-genrl").expanduser()


def default_generator(task: str) -> pathlib.Path:
    """Where the task's quickstart generator is cached (it may not exist yet)."""
    from sb3_genrl.envs import get_task

    return cache_folder() / "generators" / get_task(task).name / "vae.pt"


def default_demonstrations(task: str) -> pathlib.Path:
    """The demonstrations the task's cached generator (:func:`default_generator`) was trained on."""
    return default_generator(task).parent / "demonstrations"


def generator_settings(task: str) -> dict[str, object]:
    """What the cached generator of ``task`` is made with (recorded beside it)."""
    import sb3_genrl
    from sb3_genrl.envs import get_task
    from sb3_genrl.study.quickstart import quickstart_preset

    return {
        "task": get_task(task).name,
        "demo_episodes": DEMO_EPISODES,
        "preset": quickstart_preset(task),
        "epochs": GENERATOR_EPOCHS,
        "eval_every": GENERATOR_EVAL_EVERY,
        "seed": SEED,
        "version": sb3_genrl.__version__,
    }


def build_default_generator(
    task: str, *, device: str = "auto", progress_bar: bool = True, log: Callable[[str], None] = print
) -> pathlib.Path:
    """Make the task's quickstart generator into the cache unless it is there: demonstrations, then the beta-VAE.

    :param task: a task name or Gymnasium id
    :param device: torch device of the generator's training
    :param progress_bar: show the stages' progress bars
    :param log: called with a line before each stage
    :return: the generator's file
    """
    from sb3_genrl.envs.demonstrations import make_demonstrations
    from sb3_genrl.generative import train_generator
    from sb3_genrl.study.state import check_and_record, folder_lock

    path = default_generator(task)
    settings = generator_settings(task)
    folder = path.parent
    with folder_lock(folder):
        check_and_record(folder / "stage.json", settings, output_exists=path.exists(), folder=folder)
        if path.exists():
            return path
        dataset = default_demonstrations(task)
        if not (dataset.is_dir() and any(dataset.iterdir())):
            log(f"{settings['task']}: no generator in {folder} yet; making the quickstart's: {DEMO_EPISODES} demonstrations")
            make_demonstrations(task, DEMO_EPISODES, dataset, seed=SEED, progress_bar=progress_bar)
        log(f"{settings['task']}: training the generator {settings['preset']} for {GENERATOR_EPOCHS} epochs -> {path}")
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
