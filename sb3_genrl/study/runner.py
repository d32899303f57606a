"""``genrl study``: demonstrations -> 18 generators -> evaluation -> GenRL over seeds -> baselines -> report."""

from __future__ import annotations

import json
import os
import pathlib
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from sb3_genrl.study.jobs import baseline_job, generator_job
from sb3_genrl.study.report import write_task_report
from sb3_genrl.study.scales import SCALES, StudyScale

# PPO and SAC on the feedback task with the demonstrations, and stock algorithms on the best generator's latent space.
BASELINES = ("ppo", "sac", "latent-ppo", "latent-sac", "latent-trpo")
MODELS = tuple(f"VAE{i}" for i in range(1, 10)) + tuple(f"GAN{i}" for i in range(1, 10))


def run_study(task: str, scale: str | StudyScale, out_dir: str | os.PathLike, *, executor: str = "local",
              address: str | None = None, workers: int | None = None, models: tuple[str, ...] = MODELS, device: str = "auto",
              log: Callable[[str], None] | None = None) -> pathlib.Path:
    """Run the paper's experiments at a scale and write ``report.md`` (per task, and an index for ``task="all"``).

    Results are written as they complete and finished work is skipped on a rerun, so an interrupted study resumes.

    :param task: a task name from :data:`sb3_genrl.envs.TASKS`, or ``all`` for every registered task
    :param scale: ``smoke``, ``small`` or ``paper`` (see :data:`~sb3_genrl.study.scales.SCALES`), or a
        :class:`~sb3_genrl.study.scales.StudyScale` of one's own
    :param out_dir: the study folder
    :param executor: ``local`` (worker processes) or ``ray`` (Ray tasks, one per generator and per baseline run)
    :param address: the Ray cluster's address (``ray`` executor; ``None`` starts a local Ray)
    :param workers: local worker processes (default: the available cores)
    :param models: the generators to study (default: the 18 of paper table 1)
    :param device: torch device of every job
    :param log: called with a line of progress after each finished job
    :return: the report's path
    """
    from sb3_genrl.envs import TASKS

    if task not in (*TASKS, "all"):
        raise ValueError(f"unknown task {task!r}; expected one of {tuple(TASKS)} or 'all'")
    if not isinstance(scale, StudyScale) and scale not in SCALES:
        raise ValueError(f"unknown scale {scale!r}; expected one of {sorted(SCALES)} or a StudyScale")
    if executor not in ("local", "ray"):
        raise ValueError(f"executor must be 'local' or 'ray', got {executor!r}")
    unknown = [m for m in models if m not in MODELS]
    if unknown:
        raise ValueError(f"unknown models {unknown}; expected names among {MODELS}")
    preset = scale if isinstance(scale, StudyScale) else SCALES[scale]
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scale_name = "custom" if isinstance(scale, StudyScale) else scale
    (out / "study.json").write_text(json.dumps({"task": task, "scale": scale_name, **preset.as_dict()}, indent=2))
    run = _ray_map(address) if executor == "ray" else _local_map(workers or len(os.sched_getaffinity(0)))
    log = log or (lambda _line: None)
    reports = []
    for name in tuple(TASKS) if task == "all" else (task,):
        reports.append(_run_task(name, preset.as_dict(), out / name, run, models, device, log))
    if len(reports) == 1:
        return reports[0]
    index = out / "report.md"
    index.write_text("# GenRL study\n\n" + "\n".join(f"- [{p.parent.name}]({p.parent.name}/report.md)" for p in reports)
                     + "\n")
    return index


def _run_task(task: str, scale: dict[str, Any], task_dir: pathlib.Path, run, models, device, log) -> pathlib.Path:
    from sb3_genrl.envs.demonstrations import make_demonstrations

    dataset = task_dir / "demonstrations"
    if not dataset.exists():
        make_demonstrations(task, scale["demo_episodes"], dataset, seed=0, progress_bar=False)
    log(f"{task}: {scale['demo_episodes']} demonstrations in {dataset}")
    jobs = [(generator_job, (task, name, scale, str(dataset), str(task_dir), device)) for name in models]
    rows = []
    for row in run(jobs):
        rows.append(row)
        log(f"{task}: {row['model']} precision {row['precision']:.3f} recall {row['recall']:.3f} "
            f"mean delta {row['mean_delta']:.3f} best reward {row['score']:.3f}")
    (task_dir / "results.json").write_text(json.dumps(rows, indent=2))

    comparison = None
    if scale["baseline_episodes"] > 0:
        from sb3_genrl.baselines.compare import compare_runs

        best = max(rows, key=lambda r: r["score"])["model"]
        runs_dir = task_dir / "comparison"
        generator = str(task_dir / "generators" / f"{best}.pt")
        jobs = [(baseline_job, (algorithm, task, seed, scale["baseline_episodes"], str(dataset), scale["demo_episodes"],
                                str(runs_dir / f"{algorithm}_seed{seed}"), device, 1, generator))
                for algorithm in BASELINES for seed in range(scale["seeds"])]
        baseline_runs = list(run(jobs))
        genrl_runs = [str(p) for p in sorted((task_dir / "policies" / best).glob("seed*"))]
        comparison = compare_runs(genrl_runs + baseline_runs, runs_dir, task=task)
        log(f"{task}: GenRL ({best}) vs PPO vs SAC in {comparison}")
    return write_task_report(task, rows, task_dir, scale=scale, comparison=comparison)


def _local_map(workers: int):
    def run(jobs):
        if workers <= 1:
            for fn, args in jobs:
                yield fn(*args)
            return
        import multiprocessing

        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(fn, *args) for fn, args in jobs]
            for future in as_completed(futures):
                yield future.result()

    return run


def _ray_map(address: str | None):
    try:
        import ray
    except ImportError as error:
        raise ValueError("the ray executor needs Ray: pip install 'sb3-genrl[ray]'") from error

    def run(jobs):
        if not ray.is_initialized():
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        remote = {fn: ray.remote(num_cpus=1)(fn) for fn, _ in jobs}
        pending = [remote[fn].remote(*args) for fn, args in jobs]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])

    return run
