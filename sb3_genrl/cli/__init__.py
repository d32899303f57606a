"""The ``genrl`` command line. Each command parses its arguments, checks every value and output path before any work
(:mod:`sb3_genrl.checks`), and calls one library function that a user could call too.

One grammar for all commands: ``--task`` is a registered task (:data:`sb3_genrl.envs.TASKS`); ``--demos`` is a
demonstration dataset and ``--episodes`` / ``--demo-episodes`` are counts; ``--out`` is where the results go;
``--seed``, ``--device`` and ``--no-progress-bar`` mean the same wherever they appear.
"""

from __future__ import annotations

import argparse
import errno
import os
import sys
import time
from collections.abc import Callable

import torch

from sb3_genrl import __version__
from sb3_genrl.cli import parsers

WORKFLOW = (
    "play",
    "demos",
    "train-generator",
    "evaluate",
    "train-policy",
    "baseline",
    "compare",
    "video",
    "quickstart",
    "study",
)
# Errors that a bad argument or path raises in the library: printed as one line, exit status 2 (as argparse does).
KNOWN_ERRORS = (ValueError, FileNotFoundError, PermissionError, FileExistsError, IsADirectoryError, NotADirectoryError)


def build_parser() -> argparse.ArgumentParser:
    """The ``genrl`` parser: one sub-parser per command, in workflow order (:data:`WORKFLOW`)."""
    parser = argparse.ArgumentParser(
        prog="genrl",
        description="GenRL for Stable-Baselines3: tasks, demonstrations, generators, evaluation, policies, "
        "baselines and the paper's study.",
        epilog="The commands are listed in workflow order: play the scripted "
        "motions, make demonstrations, train a generator, evaluate it, train a GenRL policy, train baselines, compare "
        "them, render a video; quickstart and study run the whole workflow. 'genrl COMMAND --help' for its options.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands (in workflow order)")
    for add in (
        parsers.add_play,
        parsers.add_demos,
        parsers.add_train_generator,
        parsers.add_evaluate,
        parsers.add_train_policy,
        parsers.add_baseline,
        parsers.add_compare,
        parsers.add_video,
        parsers.add_quickstart,
        parsers.add_study,
    ):
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``genrl`` with ``argv`` (default: the command line). A known error is printed as one line, exit status 2;
    an interrupt (Ctrl-C) exits with 130; a failed write or read (a full disk) is one line naming the cause and the
    file, exit status 1."""
    parser = build_parser()
    args = parser.parse_args(argv)
    command: Callable[[argparse.Namespace], int] = args.func

    # The networks are small: torch's default of one thread per core only oversubscribes the cores MuJoCo and the
    # env processes use (a run took 5 times as long beside a second busy process), as the quickstart found first.
    torch.set_num_threads(1)
    try:
        try:
            return int(command(args) or 0)
        except (EOFError, BrokenPipeError, ConnectionResetError) as error:  # env processes gone: by a Ctrl-C?
            time.sleep(0.5)  # an interrupt that ended them reaches this process now, as KeyboardInterrupt
            return _fail(args.command, f"the env processes ended unexpectedly ({type(error).__name__}); see above", 1)
    except KeyboardInterrupt:
        return _fail(args.command, "interrupted; rerun the same command to resume", 130)
    except KNOWN_ERRORS as error:
        return _fail(args.command, f"error: {error}", 2)
    except OSError as error:  # a full disk, a folder gone: the cause and the file
        where = " ".join(repr(os.fspath(name)) for name in (error.filename, error.filename2) if name is not None)
        if not where and error.errno in (errno.ENOSPC, errno.EDQUOT) and getattr(args, "out", None) is not None:
            where = f"writing {os.fspath(args.out)!r}"  # a file written as it grows (the Monitor's, the logger's)
        return _fail(args.command, f"error: {error.strerror or error}{': ' + where if where else ''}", 1)
    except RuntimeError as error:
        if "PytorchStreamWriter" not in str(error) and "unexpected pos" not in str(error):
            raise
        return _fail(args.command, f"error: torch could not write a file (is the disk full?): {str(error).splitlines()[0]}", 1)


def _fail(command: str, message: str, status: int) -> int:
    print(f"genrl {command}: {message}", file=sys.stderr)
    return status
