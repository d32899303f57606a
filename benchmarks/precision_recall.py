"""Benchmark of sb3_genrl.metrics.precision_recall against prdc and against the bound of its matrix products.

Each measurement runs in a fresh subprocess that creates the data (Gaussian, ``--dim`` values per sample), records
its peak resident memory (``ru_maxrss``), runs one method and reports the time and the growth of the peak memory.
Methods:

- ``ours``: ``precision_recall(real, generated, k)`` on the CPU (torch, float32 blocks);
- ``prdc``: ``prdc.compute_prdc`` (full distance matrices with scikit-learn; same definition of precision and
  recall except that it counts a point inside a ball with ``<`` where we use ``<=``, which differs only on exact
  ties, absent from continuous random data), used as a correctness cross-check;
- ``matmul``: the three distance matrix products real-real, generated-generated and real-generated alone
  (blocked ``torch.mm`` with our block size), the bound an exact method has to pay.

``matmul`` and ``ours`` alternate ``--repeats`` times per size, so that both see the same load; each repeat's
ratio ``ours / matmul`` is recorded, and the summary gives their minimum and median. The JSON records the command,
the package versions and the git commit (:func:`sb3_genrl.provenance.provenance`) and the load average.

Usage: ``python -m benchmarks.precision_recall [--sizes 5000 15000] [--repeats 3] [--threads N] [--skip-50k] [--out PATH]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

import numpy as np
import torch

from sb3_genrl.checks import check_output_file, check_positive_int
from sb3_genrl.markdown import markdown_table
from sb3_genrl.metrics import precision_recall
from sb3_genrl.metrics.precision_recall import DEFAULT_MEMORY_BUDGET_MB, block_size
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_write_json

DEFAULT_OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "precision_recall.json")
LARGE_SIZE = 50000


def _data(size: int, dim: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    real = rng.standard_normal((size, dim), dtype=np.float32)
    generated = rng.standard_normal((size, dim), dtype=np.float32)
    return real, generated


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kilobytes on Linux


def _worker(method: str, size: int, dim: int, k: int, seed: int, threads: int | None) -> dict:
    if threads is not None:
        torch.set_num_threads(threads)

    real, generated = _data(size, dim, seed)
    if method == "prdc":
        from prdc import compute_prdc
    baseline = _peak_mb()
    start = time.perf_counter()
    result: dict = {}
    if method == "ours":
        measures = precision_recall(real, generated, k, device="cpu")
        result = {"precision": measures.precision, "recall": measures.recall}
    elif method == "prdc":
        with contextlib.redirect_stdout(io.StringIO()):
            measures = compute_prdc(real, generated, k)
        result = {"precision": float(measures["precision"]), "recall": float(measures["recall"])}
    elif method == "matmul":
        block = block_size(size, None, DEFAULT_MEMORY_BUDGET_MB)
        x, y = torch.from_numpy(real), torch.from_numpy(generated)
        with torch.no_grad():
            for a, b in ((x, x), (y, y), (x, y)):
                for i in range(0, size, block):
                    for j in range(0, size, block):
                        torch.mm(a[i : i + block], b[j : j + block].T)
    else:
        raise ValueError(f"unknown method {method!r}")
    seconds = time.perf_counter() - start
    return {
        "method": method,
        "size": size,
        "seconds": seconds,
        "peak_mb": _peak_mb() - baseline,
        **result,
        "torch_threads": torch.get_num_threads(),
    }


def _run(method: str, size: int, args: argparse.Namespace) -> dict:
    command = [
        sys.executable,
        os.path.abspath(__file__),
        "--worker",
        method,
        "--size",
        str(size),
        "--dim",
        str(args.dim),
        "--k",
        str(args.k),
        "--seed",
        str(args.seed),
        *(["--threads", str(args.threads)] if args.threads is not None else []),
    ]
    completed = subprocess.run(command, capture_output=True, text=True, check=False)
    if completed.returncode != 0:
        return {"method": method, "size": size, "error": completed.stderr.strip().splitlines()[-1:]}
    return json.loads(completed.stdout.strip().splitlines()[-1])


def _ratios(runs: list[dict], size: int) -> list[float]:
    """Each repeat's ``ours / matmul`` time at ``size`` (the runs of one repeat measured one after the other)."""
    timed = [run for run in runs if run["size"] == size and "seconds" in run and "repeat" in run]
    pairs = {}
    for run in timed:
        pairs.setdefault(run["repeat"], {})[run["method"]] = run["seconds"]
    return [pair["ours"] / pair["matmul"] for _, pair in sorted(pairs.items()) if {"ours", "matmul"} <= pair.keys()]


def _table(runs: list[dict]) -> str:
    """The runs as a Markdown table, one row per size and method: times (minimum and median over the repeats),
    peak memory, values and the time over the matrix-product bound (minimum and median of the repeats' ratios)."""
    table = []
    for size in sorted({run["size"] for run in runs}):
        for method in ("matmul", "ours", "prdc"):
            chosen = [run for run in runs if run["size"] == size and run["method"] == method]
            if not chosen:
                continue
            timed = [run for run in chosen if "seconds" in run]
            if not timed:
                table.append([size, method, len(chosen), f"failed: {chosen[0]['error']}", "", "", "", "", ""])
                continue
            seconds = [run["seconds"] for run in timed]
            ratios = _ratios(runs, size) if method == "ours" else []
            table.append(
                [
                    size,
                    method,
                    len(timed),
                    f"{min(seconds):.2f} / {statistics.median(seconds):.2f}",
                    f"{max(run['peak_mb'] for run in timed):.0f}",
                    f"{timed[0]['precision']:.4f}" if "precision" in timed[0] else "",
                    f"{timed[0]['recall']:.4f}" if "recall" in timed[0] else "",
                    f"{min(ratios):.2f} / {statistics.median(ratios):.2f}" if ratios else "",
                ]
            )
    header = ["N vs N", "method", "runs", "time (s), min / median", "peak memory (MiB)", "precision", "recall"]
    return markdown_table(header + ["time / matmul bound, min / median"], table, align="rlrrrrrr")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[5000, 15000], help="set sizes (real = generated)")
    parser.add_argument("--repeats", type=int, default=3, help="alternating runs of matmul and ours per size")
    parser.add_argument("--skip-50k", action="store_true", help="skip the 50000 vs 50000 run of ours")
    parser.add_argument("--skip-prdc", action="store_true", help="skip prdc")
    parser.add_argument("--dim", type=int, default=483, help="values per sample (69 steps x 7 joints)")
    parser.add_argument("--k", type=int, default=3, help="neighbourhood size")
    parser.add_argument("--seed", type=int, default=0, help="data seed")
    parser.add_argument("--threads", type=int, default=None, help="torch threads of each method (default: all cores)")
    parser.add_argument("--out", default=DEFAULT_OUT, help="JSON output path")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--size", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker is not None:
        print(json.dumps(_worker(args.worker, args.size, args.dim, args.k, args.seed, args.threads)))
        return 0
    # The output is checked before any work.
    for option in ("repeats", "threads"):
        try:
            if getattr(args, option) is not None:
                check_positive_int(getattr(args, option), "")
        except ValueError as error:
            parser.error(f"argument --{option}: {error}")
    try:
        check_output_file(args.out, "")
    except ValueError as error:
        parser.error(f"argument --out: {error}")

    command = "python -m benchmarks.precision_recall " + " ".join(sys.argv[1:] if argv is None else argv)
    load_before = os.getloadavg()
    runs = []
    for size in args.sizes:
        for repeat in range(args.repeats):
            for method in ("matmul", "ours"):
                runs.append(_run(method, size, args) | {"repeat": repeat})
                print(json.dumps(runs[-1]), flush=True)
        if not args.skip_prdc:
            runs.append(_run("prdc", size, args))
            print(json.dumps(runs[-1]), flush=True)
    if not args.skip_50k:
        runs.append(_run("ours", LARGE_SIZE, args))
        print(json.dumps(runs[-1]), flush=True)

    def find(method: str, size: int) -> dict | None:
        return next((r for r in runs if r["method"] == method and r["size"] == size and "seconds" in r), None)

    summary = []
    print("\n" + _table(runs))
    for size in sorted({run["size"] for run in runs}):
        ours, prdc_run = find("ours", size), find("prdc", size)
        entry = {"size": size}
        ratios = _ratios(runs, size)
        if ratios:
            entry["ours_over_matmul_bound"] = {"min": min(ratios), "median": statistics.median(ratios), "each": ratios}
        if ours and prdc_run:
            entry["speedup_over_prdc"] = prdc_run["seconds"] / ours["seconds"]
            entry["same_values_as_prdc"] = (ours["precision"], ours["recall"]) == (prdc_run["precision"], prdc_run["recall"])
        summary.append(entry)
        print(json.dumps(entry))
    atomic_write_json(
        args.out,
        {
            "command": command,
            **provenance(),
            "dim": args.dim,
            "k": args.k,
            "seed": args.seed,
            "repeats": args.repeats,
            "cpu_count": os.cpu_count(),
            "machine": platform.processor() or platform.machine(),
            "load_average_before": load_before,
            "load_average_after": os.getloadavg(),
            "runs": runs,
            "summary": summary,
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
