"""``genrl study``: demonstrations -> 18 generators -> evaluation -> GenRL over seeds -> baselines -> report.

A study folder is resumable and guarded (:mod:`sb3_genrl.run.stages`): one process at a time holds it (a lock),
each stage records the settings that made it, and a rerun whose settings differ from a stage's record is refused
before any work, with the stage folders and settings named. The reports read their numbers from these records.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import pathlib
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

import sb3_genrl
from sb3_genrl.baselines import BASELINES
from sb3_genrl.baselines.compare import compare_runs
from sb3_genrl.checks import check_device, check_output_dir, check_positive_int
from sb3_genrl.data import dataset_info
from sb3_genrl.data.fingerprints import dataset_fingerprint, file_fingerprint
from sb3_genrl.envs import arm_tasks
from sb3_genrl.envs.demonstrations import make_demonstrations
from sb3_genrl.provenance import package_versions
from sb3_genrl.run.stages import (
    STAGE_FILE,
    check_and_record,
    exit_with_parent,
    read_settings,
    refuse_conflicts,
    settings_conflicts,
)
from sb3_genrl.run.train import effective_genrl_settings
from sb3_genrl.study.cluster import DEFAULT_CONNECT_TIMEOUT, connect_ray
from sb3_genrl.study.jobs import (
    EVALUATION_SEED,
    GENERATOR_SEED,
    INTERVENTIONS,
    PRIOR_ROLLOUT_SEED,
    K,
    baseline_job,
    generator_job,
    task_genrl_kwargs,
)
from sb3_genrl.study.report import write_all_tasks_report, write_task_report
from sb3_genrl.study.scales import SCALES, StudyScale, task_scale
from sb3_genrl.utils import atomic_write_json, atomic_write_text, folder_lock

MODELS = tuple(f"VAE{i}" for i in range(1, 10)) + tuple(f"GAN{i}" for i in range(1, 10))
DEMONSTRATION_SEED = 0


def run_study(
    task: str,
    scale: str | StudyScale,
    out_dir: str | os.PathLike,
    *,
    executor: str = "local",
    address: str | None = None,
    workers: int | None = None,
    models: tuple[str, ...] = MODELS,
    device: str = "auto",
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT,
    log: Callable[[str], None] | None = None,
) -> pathlib.Path:
    """Run the paper's experiments at a scale and write ``report.md`` (per task, and an index for ``task="all"``).

    Results are written as they complete and finished work is skipped on a rerun, so an interrupted study resumes.
    A rerun with settings that differ from those recorded in the folder raises
    :class:`~sb3_genrl.run.stages.SettingsConflictError` before any work; a folder that another process is
    working in raises :class:`~sb3_genrl.utils.FolderInUseError`.

    :param task: a task name from :func:`sb3_genrl.envs.arm_tasks`, or ``all`` for all of them
    :param scale: ``smoke``, ``small`` or ``paper`` (see :data:`~sb3_genrl.study.scales.SCALES`), or a
        :class:`~sb3_genrl.study.scales.StudyScale` of one's own
    :param out_dir: the study folder
    :param executor: ``local`` (worker processes) or ``ray`` (Ray tasks, one per generator and per baseline run)
    :param address: the Ray cluster's address (``ray`` executor; ``None`` starts a local Ray)
    :param workers: local worker processes (default: the available cores)
    :param models: the generators to study (default: the 18 of paper table 1)
    :param device: torch device of every job
    :param connect_timeout: seconds allowed to connect to the Ray cluster at ``address``
    :param log: called with a line of progress after each finished job
    :return: the report's path
    """
    if task not in (*arm_tasks(), "all"):  # the study's baselines and measures are those of the arm's tasks
        raise ValueError(f"unknown task {task!r} for the study; expected one of {arm_tasks()} or 'all'")
    if not isinstance(scale, StudyScale) and scale not in SCALES:
        raise ValueError(f"unknown scale {scale!r}; expected one of {sorted(SCALES)} or a StudyScale")
    if executor not in ("local", "ray"):
        raise ValueError(f"executor must be 'local' or 'ray', got {executor!r}")
    if address is not None and executor != "ray":  # else the study would run here, not on the cluster asked for
        raise ValueError(f"address {address!r} is a Ray cluster's, which needs executor='ray' (--executor ray)")
    unknown = [m for m in models if m not in MODELS]
    if unknown:
        raise ValueError(f"unknown models {unknown}; expected names among {MODELS}")
    if workers is not None:
        check_positive_int(workers, "workers")
    check_device(device)
    settings = (scale if isinstance(scale, StudyScale) else SCALES[scale]).as_dict()
    tasks = arm_tasks() if task == "all" else (task,)
    out = check_output_dir(out_dir)
    log = log or (lambda _line: None)
    with folder_lock(out):
        refuse_conflicts(out, [line for name in tasks for line in _conflicts(name, task_scale(settings, name), out / name)])
        run = _ray_map(address, connect_timeout) if executor == "ray" else _local_map(workers or len(os.sched_getaffinity(0)))
        atomic_write_json(
            out / "study.json",
            {
                "task": task,
                "scale": "custom" if isinstance(scale, StudyScale) else scale,
                **settings,
                "packages": package_versions(),
            },
        )
        reports = [_run_task(name, task_scale(settings, name), out / name, run, models, device, log) for name in tasks]
        index = _write_index(out)
    return reports[0] if len(reports) == 1 else index


def _write_index(out: pathlib.Path) -> pathlib.Path:
    """``report.md`` linking each task's report in ``out``, and, once every arm task has finished (in this run or an
    earlier one into the same folder), the pooled table over the tasks (paper table 6)."""
    finished = {name: out / name / "results.json" for name in arm_tasks() if (out / name / "report.md").is_file()}
    lines = ["# GenRL study", "", *(f"- [{name}]({name}/report.md)" for name in finished)]
    if len(finished) == len(arm_tasks()):
        rows = {name: json.loads(path.read_text()) for name, path in finished.items()}
        lines.append(f"- [all tasks]({write_all_tasks_report(rows, out).name}): paper table 6, the tasks pooled")
    index = out / "report.md"
    atomic_write_text(index, "\n".join(lines) + "\n")
    return index


def _demonstration_settings(task: str, scale: dict[str, Any]) -> dict[str, Any]:
    return {"task": task, "episodes": scale["demo_episodes"], "seed": DEMONSTRATION_SEED, "version": sb3_genrl.__version__}


def _stages(
    task: str, task_dir: pathlib.Path, scale: dict[str, Any], dataset: str | None
) -> list[tuple[pathlib.Path, dict, bool]]:
    """Each stage's record, this run's settings for it and whether it has output. ``dataset`` is the fingerprint
    of the demonstrations (None: not known yet, left out of the settings)."""
    made_from = {} if dataset is None else {"dataset": dataset}
    generators, evaluation, policies, comparison = (
        task_dir / name for name in ("generators", "evaluation", "policies", "comparison")
    )
    stages = [
        (
            generators / STAGE_FILE,
            {"epochs": scale["generator_epochs"], "eval_every": scale["eval_every"], "seed": GENERATOR_SEED, **made_from},
            any(generators.glob("*.pt")),
        ),
        (
            evaluation / STAGE_FILE,
            {
                "n": scale["pr_samples"],
                "dwpr_n": scale["dwpr_samples"],
                "k": K,
                "interventions": INTERVENTIONS,
                "seed": EVALUATION_SEED,
                "prior_contexts": scale["prior_contexts"],
                "prior_draws": scale["prior_draws"],
                "prior_seed": PRIOR_ROLLOUT_SEED,
                **made_from,
            },
            any(path.name != STAGE_FILE for path in evaluation.glob("*.json")),
        ),
        (
            policies / STAGE_FILE,
            {
                "episodes": scale["policy_episodes"],
                "batch_episodes": scale["batch_episodes"],
                "genrl_kwargs": task_genrl_kwargs(task),
                # every GenRL setting in effect, GenRL's defaults included
                "genrl": effective_genrl_settings(task_genrl_kwargs(task), scale["batch_episodes"], n_envs=1),
            },
            any(policies.glob("*/seed*/summary.json")),
        ),
    ]
    if scale["baseline_episodes"] > 0:
        stages.append(
            (
                comparison / STAGE_FILE,
                {"episodes": scale["baseline_episodes"], "demo_episodes": scale["demo_episodes"], **made_from},
                any(comparison.glob("*/summary.json")),
            )
        )
    return stages


def _conflicts(task: str, scale: dict[str, Any], task_dir: pathlib.Path) -> list[str]:
    """What of ``task_dir`` was made with other settings than ``scale`` (checked before any work)."""
    dataset = task_dir / "demonstrations"
    lines = []
    if dataset.is_dir() and any(dataset.iterdir()):
        lines += settings_conflicts(dataset, dataset_info(dataset), _demonstration_settings(task, scale))
    for record, wanted, exists in _stages(task, task_dir, scale, None):
        lines += settings_conflicts(record.parent, read_settings(record), wanted, output_exists=exists)
    return lines


def _run_task(task: str, scale: dict[str, Any], task_dir: pathlib.Path, run, models, device, log) -> pathlib.Path:
    dataset = task_dir / "demonstrations"
    if not dataset.is_dir() or not any(dataset.iterdir()):
        make_demonstrations(task, scale["demo_episodes"], dataset, seed=DEMONSTRATION_SEED, progress_bar=False)
    log(f"{task}: {scale['demo_episodes']} demonstrations in {dataset}")
    fingerprint = dataset_fingerprint(dataset)
    stages = _stages(task, task_dir, scale, fingerprint)
    for record, wanted, exists in stages[:3]:
        check_and_record(record, wanted, output_exists=exists, folder=task_dir)
    jobs = [(generator_job, (task, name, scale, str(dataset), str(task_dir), device)) for name in models]
    rows = []
    for row in run(jobs):
        rows.append(row)
        log(
            f"{task}: {row['model']} precision {row['precision']:.3f} recall {row['recall']:.3f} "
            f"mean delta {row['mean_delta']:.3f} coverage {row['coverage']:.3f} prior median {row['prior_median']:.3f} "
            f"best reward {row['score']:.3f} (half budget {row['half_score']:.3f}) final {row['final']:.3f}"
        )
    # the jobs finish in any order; the models' order makes the tables and the bootstrap intervals reproducible
    rows.sort(key=lambda row: list(models).index(row["model"]))
    atomic_write_json(task_dir / "results.json", rows)

    comparison = None
    if scale["baseline_episodes"] > 0:
        best = max(rows, key=lambda r: r["score"])["model"]
        runs_dir = task_dir / "comparison"
        generator = str(task_dir / "generators" / f"{best}.pt")
        record, wanted, exists = stages[3]
        check_and_record(
            record, {**wanted, "generator": f"{best} {file_fingerprint(generator)}"}, output_exists=exists, folder=task_dir
        )
        jobs = [
            (
                baseline_job,
                (
                    algorithm,
                    task,
                    seed,
                    scale["baseline_episodes"],
                    str(dataset),
                    scale["demo_episodes"],
                    str(runs_dir / f"{algorithm}_seed{seed}"),
                    device,
                    1,
                    generator,
                    scale["bc_eval_goals"],
                ),
            )
            for algorithm in BASELINES
            for seed in range(scale["seeds"])
        ]
        baseline_runs = list(run(jobs))
        genrl_runs = [str(task_dir / "policies" / best / f"seed{seed}") for seed in range(scale["seeds"])]
        comparison = compare_runs(genrl_runs + baseline_runs, runs_dir, task=task)
        log(f"{task}: GenRL ({best}) vs PPO vs SAC in {comparison}")
    return write_task_report(
        task, rows, task_dir, scale=_recorded_scale(task_dir, dataset, rows, comparison), comparison=comparison
    )


def _recorded_scale(
    task_dir: pathlib.Path, dataset: pathlib.Path, rows: list[dict[str, Any]], comparison: pathlib.Path | None
) -> dict[str, Any]:
    """The settings the report states, read from what the stages recorded (not from this run's request)."""
    generators, evaluation, policies = (
        read_settings(task_dir / name / STAGE_FILE) for name in ("generators", "evaluation", "policies")
    )
    baselines = read_settings(task_dir / "comparison" / STAGE_FILE) if comparison is not None else {"episodes": 0}
    return {
        "demo_episodes": dataset_info(dataset)["episodes"],
        "generator_epochs": generators["epochs"],
        "eval_every": generators["eval_every"],
        "pr_samples": evaluation["n"],
        "dwpr_samples": evaluation["dwpr_n"],
        "prior_contexts": evaluation["prior_contexts"],
        "prior_draws": evaluation["prior_draws"],
        "policy_episodes": policies["episodes"],
        "batch_episodes": policies["batch_episodes"],
        "seeds": min(len(row["rewards"]) for row in rows),
        "baseline_episodes": baselines["episodes"],
    }


def _local_map(workers: int):
    def run(jobs):
        if workers <= 1:
            for fn, args in jobs:
                yield fn(*args)
            return

        # The workers exit when this process dies (even on kill -9), so none finishes a stale job after it.
        with ProcessPoolExecutor(
            max_workers=workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=exit_with_parent,
            initargs=(os.getpid(),),
        ) as pool:
            futures = [pool.submit(fn, *args) for fn, args in jobs]
            for future in as_completed(futures):
                yield future.result()

    return run


def _ray_map(address: str | None, connect_timeout: float = DEFAULT_CONNECT_TIMEOUT):
    try:
        import ray
    except ImportError as error:
        raise ValueError("the ray executor needs Ray: pip install 'sb3-genrl[ray]'") from error

    connect_ray(address, connect_timeout, include_dashboard=False, log_to_driver=False)

    def run(jobs):
        remote = {fn: ray.remote(num_cpus=1)(fn) for fn, _ in jobs}
        pending = [remote[fn].remote(*args) for fn, args in jobs]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])

    return run
