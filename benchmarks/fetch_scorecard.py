"""Does the generator scorecard predict GenRL's result on a Fetch task? A few generators of the Fetch recipe's family,
each scored before any policy training and then trained on with GenRL's one Fetch configuration.

For each ``--variants`` entry (the ``VAE-FETCH`` recipe with some of its settings changed, ``""`` for the recipe
itself), trained ``--epochs`` epochs with seed 0 on the task's demonstrations:

1. the scorecard of ``genrl evaluate --task`` (:func:`sb3_genrl.metrics.evaluate_generator`): precision, recall,
   density, coverage and DwPR against the demonstrations, and the prior rollout through the step path
   (``--contexts`` reset states from :data:`~sb3_genrl.metrics.prior_rollout.PRIOR_ROLLOUT_SEED` x ``--draws``
   prior draws: the share of states some draw solves);
2. the fitted start: GenRL's policy mean fitted to the demonstrations (the entry's ``DemonstrationCallback`` fit),
   its success on ``--tuning-states`` tuning states (:data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED`), the measure the
   Fetch benchmark chooses its generator by;
3. GenRL with the task's entry in ``hyperparams/genrl.yml`` for ``--episodes`` (default: the entry's), seed 0, then
   the deterministic policy's success on ``--eval-states`` held-out initial states
   (:data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`).

Then each measure's Pearson R and Spearman rho against the final success over the generators, with 95% bootstrap
intervals (:func:`sb3_genrl.metrics.correlation_table`). Each generator's row is written to ``--out`` as it finishes
and the same command resumes (a row of other settings is refused); its Markdown table beside it.

    python -m benchmarks.fetch_scorecard --task fetch-push --data runs/fetch/fetch-push/demonstrations
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time

import numpy as np
import torch
from sb3_genrl.envs import get_task
from sb3_genrl.envs.demonstrations.fetch import evaluate_success

from benchmarks.fetch_seed import fitted_mean_success
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, check_output_dir
from sb3_genrl.data import load_actions
from sb3_genrl.generative import load
from sb3_genrl.generative.presets import resolve_generator_spec
from sb3_genrl.generative.vae import BetaVAE
from sb3_genrl.genrl import GenRL
from sb3_genrl.hyperparams import EVAL_GOAL_SEED, TUNING_GOAL_SEED
from sb3_genrl.markdown import markdown_table
from sb3_genrl.metrics import correlation_table, evaluate_generator, real_subset
from sb3_genrl.metrics.prior_rollout import PRIOR_ROLLOUT_SEED
from sb3_genrl.provenance import provenance
from sb3_genrl.run import train_policy
from sb3_genrl.study.quickstart import task_settings
from sb3_genrl.utils import atomic_write_json, atomic_write_text

FETCH_TASKS = ("fetch-reach", "fetch-push", "fetch-pick-and-place", "fetch-slide")
RECIPE = "VAE-FETCH"
# the recipe, then fewer latent dimensions (VAE6's 3 and VAE9's 6), eq. 9 without the path term, a larger beta
VARIANTS = ("", "latent_dim=6", "latent_dim=3", "path_weight=0", "beta=0.01")
MEASURES = ("precision", "recall", "density", "coverage", "delta_1", "mean_delta", "prior_success", "fitted_start")
KEYS = {"latent_dim": int, "beta": float, "path_weight": float}


def variant_spec(variant: str) -> dict[str, float]:
    """``"latent_dim=6,path_weight=0"`` as ``{"latent_dim": 6, "path_weight": 0.0}`` (``""``: the recipe itself)."""
    spec: dict[str, float] = {}
    for part in filter(None, variant.split(",")):
        key, _, value = part.partition("=")
        if key not in KEYS or not value:
            raise argparse.ArgumentTypeError(f"variant {variant!r}: expected KEY=VALUE pairs with KEY among {sorted(KEYS)}")
        try:
            spec[key] = KEYS[key](value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"variant {variant!r}: {key} must be a number, got {value!r}") from None
    return spec


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True, choices=FETCH_TASKS)
    parser.add_argument("--data", type=EXISTING, required=True, help="the task's demonstrations (genrl demos --task)")
    parser.add_argument(
        "--variants",
        nargs="+",
        default=list(VARIANTS),
        help=f"the {RECIPE} recipe with these settings changed, e.g. latent_dim=6,path_weight=0 ('' for the recipe)",
    )
    parser.add_argument("--epochs", type=COUNT, default=300, help="generator epochs (default 300, the benchmark's)")
    parser.add_argument("--episodes", type=COUNT, default=None, help="GenRL episodes (default: the task's entry)")
    parser.add_argument("--eval-states", type=COUNT, default=500, help="held-out initial states (default 500)")
    parser.add_argument("--tuning-states", type=COUNT, default=100, help="tuning states of the fitted start")
    parser.add_argument("--contexts", type=COUNT, default=64, help="prior rollout: reset states (default 64)")
    parser.add_argument("--draws", type=COUNT, default=16, help="prior rollout: draws per state (default 16)")
    parser.add_argument("--pr-samples", type=COUNT, default=2000, help="precision/recall samples (the study's 2000)")
    parser.add_argument("--dwpr-samples", type=COUNT, default=1000, help="DwPR samples per intervention (1000)")
    parser.add_argument("--work", default=None, help="generators and GenRL runs (default runs/fetch_scorecard/TASK)")
    parser.add_argument(
        "--out",
        type=JSON_OUT,
        default=None,
        help="JSON (default benchmarks/results/fetch_scorecard_TASK.json; Markdown beside it)",
    )
    args = parser.parse_args(argv)
    specs = [variant_spec(variant) for variant in args.variants]
    if len({json.dumps(spec, sort_keys=True) for spec in specs}) != len(specs):
        parser.error("--variants: each variant must differ")
    here = os.path.dirname(os.path.abspath(__file__))
    args.out = args.out or os.path.join(here, "results", f"fetch_scorecard_{args.task}.json")
    args.work = str(check_output_dir(args.work or os.path.join("runs", "fetch_scorecard", args.task)))
    args.episodes = args.episodes or task_settings(args.task)[0]
    return args


def settings_of(args: argparse.Namespace) -> dict[str, object]:
    """What every row shares: checked when the JSON is continued."""
    return {
        "task": args.task,
        "env_id": get_task(args.task).env_id,
        "data": os.path.abspath(args.data),
        "recipe": resolve_generator_spec(RECIPE),
        "epochs": args.epochs,
        "episodes": args.episodes,
        "eval_states": args.eval_states,
        "eval_seed": EVAL_GOAL_SEED,
        "tuning_states": args.tuning_states,
        "tuning_seed": TUNING_GOAL_SEED,
        "contexts": args.contexts,
        "draws": args.draws,
        "prior_seed": PRIOR_ROLLOUT_SEED,
        "pr_samples": args.pr_samples,
        "dwpr_samples": args.dwpr_samples,
        "genrl_settings": task_settings(args.task)[2],
    }


def generator_row(args: argparse.Namespace, variant: str, actions: np.ndarray) -> dict[str, object]:
    """One generator: trained, scored, then trained on with GenRL and evaluated."""
    name = variant or RECIPE
    folder = os.path.join(args.work, name.replace("=", "-").replace(",", "_"))
    os.makedirs(folder, exist_ok=True)
    spec = {key: value for key, value in resolve_generator_spec(RECIPE).items() if key != "model"} | variant_spec(variant)
    path = os.path.join(folder, "vae.pt")
    begin = time.perf_counter()
    if not os.path.exists(path):  # written atomically by save(): present only once trained
        vae = BetaVAE(
            actions.shape[1],
            actions.shape[2],
            spec["latent_dim"],
            beta=spec["beta"],
            path_weight=spec["path_weight"],
            device="cpu",
        )
        vae.fit(actions, epochs=args.epochs, seed=0, progress_bar=False).save(path)
    generator = load(path, device="cpu")
    trained = time.perf_counter()
    score = evaluate_generator(
        generator,
        real_subset(actions, args.pr_samples, 0),
        n=args.pr_samples,
        dwpr_n=args.dwpr_samples,
        seed=0,
        name=name,
        device="cpu",
        task=args.task,
        contexts=args.contexts,
        draws=args.draws,
        prior_seed=PRIOR_ROLLOUT_SEED,
    )
    fitted = fitted_mean_success(args.task, path, args.data, args.tuning_states, TUNING_GOAL_SEED)
    scored = time.perf_counter()
    _, batch_episodes, genrl_kwargs = task_settings(args.task)
    run = train_policy(
        args.task,
        path,
        episodes=args.episodes,
        seed=0,
        out_dir=os.path.join(folder, "genrl"),
        batch_episodes=batch_episodes,
        demonstrations=args.data,
        device="cpu",
        **genrl_kwargs,
    )
    model = GenRL.load(run["model_path"], generator=generator, device="cpu")
    success = evaluate_success(model, args.task, episodes=args.eval_states, seed=EVAL_GOAL_SEED)["success_rate"]
    row = score.row()
    return {
        "variant": variant,
        "model": name,
        "spec": spec,
        **{key: row[key] for key in MEASURES if key in row},
        "prior_median": row["prior_median"],
        "fitted_start": fitted,
        "episodes": run["episodes"],
        "final_success": float(success),
        "seconds": {"generator": trained - begin, "scorecard": scored - trained, "genrl": time.perf_counter() - scored},
    }


def write(args: argparse.Namespace, result: dict) -> None:
    """The JSON, then its Markdown: the rows and, with 3 rows or more, each measure's correlation with the success."""
    rows = result["rows"]
    if len(rows) >= 3:
        table = correlation_table(rows, score_key="final_success", measure_names=list(MEASURES))
        result["correlation"] = [dataclasses.asdict(row) for row in table.rows]
    atomic_write_json(args.out, result)
    header = ["generator", *MEASURES, "GenRL final success"]
    lines = [
        f"# Generator scorecard against GenRL on {args.task}",
        "",
        f"`{result['command']}`: {len(rows)} generators, GenRL {args.episodes} episodes (seed 0), success of the "
        f"deterministic policy on {args.eval_states} held-out initial states.",
        "",
        markdown_table(
            header,
            [[row["model"], *(row[key] for key in MEASURES), row["final_success"]] for row in rows],
            align="l" + "r" * (len(header) - 1),
        ),
        "",
    ]
    if len(rows) >= 3:
        lines += ["Each measure against the final success, over the generators:", "", table.to_markdown()]
    atomic_write_text(os.path.splitext(args.out)[0] + ".md", "\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> None:
    args = arguments(argv)
    torch.set_num_threads(1)
    settings = settings_of(args)
    result = {
        "benchmark": f"fetch_scorecard_{args.task}",
        "settings": settings,
        "rows": [],
        "command": "python -m benchmarks.fetch_scorecard " + " ".join(argv if argv is not None else sys.argv[1:]),
        **provenance(),
    }
    if os.path.exists(args.out):
        with open(args.out) as file:
            result = json.load(file)
        if result.get("settings") != settings:
            differ = sorted(key for key in settings if result.get("settings", {}).get(key) != settings[key])
            raise SystemExit(f"{args.out} holds rows of other settings ({', '.join(differ)} differ): give another --out")
    actions = load_actions(args.data)
    for variant in args.variants:
        if any(row["variant"] == variant for row in result["rows"]):
            continue
        row = generator_row(args, variant, actions)
        result["rows"].append(row)
        write(args, result)
        print(json.dumps({key: row[key] for key in ("model", *MEASURES, "final_success")}), flush=True)
    write(args, result)


if __name__ == "__main__":
    main()
