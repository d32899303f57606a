"""``python -m sb3_genrl.zoo SCRIPT ARGS...``: rl-zoo3's ``train``, ``enjoy`` or ``record_video``, with GenRL registered
(:func:`sb3_genrl.zoo.register`); ``train --algo genrl`` reads ``hyperparams/genrl.yml`` unless ``-conf`` names
another file, and runs with :class:`~sb3_genrl.zoo.experiment.GenRLExperimentManager`."""

from __future__ import annotations

import runpy
import sys

SCRIPTS = ("train", "enjoy", "record_video")
USAGE = f"usage: python -m sb3_genrl.zoo {{{','.join(SCRIPTS)}}} [rl-zoo3 arguments...]"


def main(argv: list[str] | None = None) -> int:
    """Run one of rl-zoo3's scripts with ``argv`` (default: the command line's)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] in (["-h"], ["--help"]):
        print(f"{USAGE}\n(each script's own options: python -m sb3_genrl.zoo SCRIPT --help)")
        return 0
    if not argv or argv[0] not in SCRIPTS:
        print(USAGE if not argv else f"{USAGE}\nunknown script {argv[0]!r}", file=sys.stderr)
        return 2
    from sb3_genrl.zoo import register

    register()
    script, arguments = argv[0], argv[1:]
    if script == "train" and _algo(arguments) == "genrl" and not {"-conf", "--conf-file"} & set(arguments):
        from sb3_genrl.hyperparams import hyperparams_file

        arguments += ["--conf-file", str(hyperparams_file("genrl"))]
    saved_argv, sys.argv = sys.argv, [f"rl_zoo3.{script}", *arguments]
    try:
        if script == "train":
            import rl_zoo3.train

            from sb3_genrl.zoo.experiment import GenRLExperimentManager

            rl_zoo3.train.ExperimentManager = GenRLExperimentManager  # train() builds the manager by this name
            rl_zoo3.train.train()
        elif script == "enjoy":
            from rl_zoo3.enjoy import enjoy

            enjoy()
        else:  # rl-zoo3's record_video is a script without a function
            runpy.run_module("rl_zoo3.record_video", run_name="__main__", alter_sys=True)
    finally:
        sys.argv = saved_argv
    return 0


def _algo(arguments: list[str]) -> str:
    """The ``--algo`` of rl-zoo3's arguments (rl-zoo3's default, ``ppo``, when none)."""
    for index, argument in enumerate(arguments):
        if argument == "--algo" and index + 1 < len(arguments):
            return arguments[index + 1]
        if argument.startswith("--algo="):
            return argument.split("=", 1)[1]
    return "ppo"


if __name__ == "__main__":
    sys.exit(main())
