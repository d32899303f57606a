"""``python -m sb3_genrl.zoo SCRIPT ARGS...``: rl-zoo3's ``train``, ``enjoy`` or ``record_video``, with GenRL registered
(:func:`sb3_genrl.zoo.register`), or ``build-generator``, which makes a task's cached generator ahead of its first run.

``train`` parses its arguments with rl-zoo3's own parser, so every spelling that parser accepts means what it means
to rl-zoo3 (``--conf-file=mine.yml``, ``-conf mine.yml``, ``--conf mine.yml``, ...); ``--algo genrl`` then reads
``hyperparams/genrl.yml`` unless the arguments name another settings file, and runs with
:class:`~sb3_genrl.zoo.experiment.GenRLExperimentManager`. A user's mistake (an unknown env id, an env without an
entry, a bad setting, a generator cache that cannot be used) is printed as one line, exit status 2.
"""

from __future__ import annotations

import argparse
import os
import runpy
import sys
import traceback
import types

import gymnasium as gym

from sb3_genrl.checks import check_device, option
from sb3_genrl.cli import KNOWN_ERRORS
from sb3_genrl.envs import get_task
from sb3_genrl.envs.fetch import FETCH_IDS
from sb3_genrl.envs.fetch_mujoco import ROBOTICS_HINT
from sb3_genrl.hyperparams import hyperparams_file
from sb3_genrl.zoo import register
from sb3_genrl.zoo.generators import build_default_generator, check_cache, default_generator

SCRIPTS = ("train", "enjoy", "record_video", "build-generator")
USAGE = f"usage: python -m sb3_genrl.zoo {{{','.join(SCRIPTS)}}} [arguments...]"


def main(argv: list[str] | None = None) -> int:
    """Run one of rl-zoo3's scripts, or ``build-generator``, with ``argv`` (default: the command line's). A user's
    mistake is printed as one line (exit status 2; 1 for a failed read or write), without a traceback."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] in (["-h"], ["--help"]):
        print(f"{USAGE}\n(each script's own options: python -m sb3_genrl.zoo SCRIPT --help)")
        return 0
    if not argv or argv[0] not in SCRIPTS:
        print(USAGE if not argv else f"{USAGE}\nunknown script {argv[0]!r}", file=sys.stderr)
        return 2
    script, arguments = argv[0], argv[1:]
    try:
        if script == "build-generator":
            return build_generator(arguments)
        return run_script(script, arguments)
    except (*KNOWN_ERRORS, gym.error.Error) as error:
        return _fail(script, f"error: {error}", 2)
    except AssertionError as error:  # rl-zoo3 checks its arguments with assert (a missing folder, -i not a .zip)
        if not str(error) or not _raised_in_rl_zoo3(error):
            raise
        return _fail(script, f"error: {error}", 2)
    except OSError as error:  # a full disk: the cause and the file
        where = " ".join(repr(os.fspath(name)) for name in (error.filename, error.filename2) if name is not None)
        return _fail(script, f"error: {error.strerror or error}{': ' + where if where else ''}", 1)


def run_script(script: str, arguments: list[str]) -> int:
    """Run rl-zoo3's ``script`` with ``arguments``, GenRL registered; ``train`` with GenRL's experiment manager and
    its parsed arguments completed and checked by :func:`checked_train_arguments`."""
    register()
    saved_argv, sys.argv = sys.argv, [f"rl_zoo3.{script}", *arguments]
    try:
        if script == "train":
            import rl_zoo3.train

            from sb3_genrl.zoo.experiment import GenRLExperimentManager

            rl_zoo3.train.ExperimentManager = GenRLExperimentManager  # train() builds the manager by this name
            module_argparse = rl_zoo3.train.argparse  # train() builds its parser with argparse.ArgumentParser
            rl_zoo3.train.argparse = types.SimpleNamespace(ArgumentParser=_CheckedTrainParser)  # type: ignore[assignment]
            try:
                rl_zoo3.train.train()
            finally:
                rl_zoo3.train.argparse = module_argparse
        elif script == "enjoy":
            from rl_zoo3.enjoy import enjoy

            enjoy()
        else:  # rl-zoo3's record_video is a script without a function
            runpy.run_module("rl_zoo3.record_video", run_name="__main__", alter_sys=True)
    finally:
        sys.argv = saved_argv
    return 0


class _CheckedTrainParser(argparse.ArgumentParser):
    """rl-zoo3's ``train`` parser (rl-zoo3 builds and fills it inside ``train()``), whose parsed arguments pass
    :func:`checked_train_arguments` before rl-zoo3 reads them."""

    def parse_args(self, args: list[str] | None = None, namespace: argparse.Namespace | None = None) -> argparse.Namespace:  # type: ignore[override]
        try:
            parsed = super().parse_args(args, namespace)
        except (NameError, SyntaxError) as error:  # rl-zoo3 reads each -params value with eval()
            raise ValueError(
                f"-params: a value is not a Python literal ({error}); rl-zoo3 evaluates each KEY:VALUE's value, so "
                "a text goes in quotes (KEY:'text')"
            ) from None
        return checked_train_arguments(parsed)


def checked_train_arguments(args: argparse.Namespace) -> argparse.Namespace:
    """rl-zoo3's parsed ``train`` arguments, with ``--algo genrl``'s settings file (``hyperparams/genrl.yml``) when
    they name none, a Fetch env id refused, naming the extra to install, when Gymnasium-Robotics is missing, and a
    budget (``-n``) below 1 refused (rl-zoo3 would train the entry's whole budget instead).

    :param args: the arguments as rl-zoo3's parser parsed them (changed in place)
    :return: ``args``
    :raises ValueError: for a Fetch env id without Gymnasium-Robotics, or ``-n`` below 1 (other than rl-zoo3's -1)
    """
    check_env_id(args.env)
    if args.n_timesteps != -1 and args.n_timesteps < 1:  # rl-zoo3 would fall back to the entry's budget
        raise ValueError(
            f"-n/--n-timesteps must be a positive integer (left out: the entry's n_timesteps), got {args.n_timesteps}"
        )
    if args.algo == "genrl" and args.conf_file is None:
        args.conf_file = str(hyperparams_file("genrl"))
    return args


def check_env_id(env_id: str) -> None:
    """Refuse a Fetch env id that is not registered because Gymnasium-Robotics (the ``robotics`` extra) is missing;
    rl-zoo3 and Gymnasium name other unknown ids themselves.

    :param env_id: a Gymnasium id
    :raises ValueError: naming the extra
    """
    if env_id in FETCH_IDS and env_id not in gym.registry:
        raise ValueError(f"{env_id} is not available: {ROBOTICS_HINT}")


def build_generator(arguments: list[str]) -> int:
    """``build-generator --env ID``: make the task's cached generator (:mod:`sb3_genrl.zoo.generators`) now, so that
    the first ``train --algo genrl`` of the task starts training at once."""
    parser = argparse.ArgumentParser(
        prog="python -m sb3_genrl.zoo build-generator",
        description="Make a task's generator into the cache ($SB3_GENRL_CACHE, default ~/.cache/sb3-genrl) ahead of "
        "its first 'train --algo genrl': the quickstart's demonstrations and beta-VAE. Nothing is made when it is "
        "there already.",
    )
    parser.add_argument("--env", required=True, help="the task's Gymnasium id, e.g. GenRL/Hockey-v0")
    parser.add_argument("--device", type=option(check_device), default="auto", help="torch device of the training")
    parser.add_argument("--no-progress-bar", action="store_true", help="no progress bars")
    args = parser.parse_args(arguments)
    check_env_id(args.env)
    env_id = get_task(args.env).env_id
    path = default_generator(env_id)
    if path.is_file():
        check_cache(env_id)
        print(f"{env_id}: the generator {path} is made already")
        return 0
    build_default_generator(env_id, device=args.device, progress_bar=not args.no_progress_bar, log=print)
    print(f"{env_id}: the generator {path} is made; train --algo genrl --env {env_id} uses it")
    return 0


def _raised_in_rl_zoo3(error: BaseException) -> bool:
    frames = traceback.extract_tb(error.__traceback__)
    return bool(frames) and f"{os.sep}rl_zoo3{os.sep}" in frames[-1].filename


def _fail(script: str, message: str, status: int) -> int:
    print(f"python -m sb3_genrl.zoo {script}: {message}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
