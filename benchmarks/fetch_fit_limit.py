"""How far can GenRL's policy mean get on a Fetch task if the search found a solving latent action for every state?

GenRL's deterministic policy is its mean, an MLP of the context fitted by regression (to the demonstrations, then by
the E- and M-steps). This benchmark separates what the search finds from what the mean can hold:

1. the start: the mean fitted to the demonstrations as the task's entry fits it (policy seed 0), or with ``--policy``
   a trained GenRL policy (a run's ``genrl_policy.zip``), its success on ``--tuning-states`` tuning states
   (:data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED`) and on the first ``--fit-states`` of the collection states;
2. the collection: ``--states`` initial states (reset seeds from ``--collection-seed``, neither the tuning's nor the
   evaluation's), ``--draws`` latent actions each from the start's own spread around its mean, played; per state the
   solving draw nearest the mean, and the mean of its solving draws;
3. the targets themselves, played again at the first ``--fit-states`` collection states: what the mean would solve
   there if it reproduced them exactly (the best a search around the start can give);
4. the mean fitted from scratch (the entry's fit: its width, steps, learning rate and batch size) to each state's
   nearest solving draw, to those plus the demonstrations, to the start's own mean at every collection state (can a
   fit reproduce a map the network holds?), to the start's mean where it solves and the nearest solving draw
   elsewhere, and with each of ``--variants`` (other widths, steps, learning rates, batch sizes) to the nearest
   solving draws: its residual error and its success on the same ``--fit-states`` states (which it was fitted to)
   and on the tuning states.

The collection is kept beside the output (``OUT_collection.npz``) and reused by a rerun of the same settings.

A gap between 3 and 4 on the states the mean was fitted to says that the mean cannot represent the solving latent
actions, whatever search finds them. The held-out evaluation states are never used.

    python -m benchmarks.fetch_fit_limit --task fetch-push --generator GEN.pt --data DEMOS
    python -m benchmarks.fetch_fit_limit --task fetch-slide --generator GEN.pt --data DEMOS --policy RUN/genrl_policy.zip
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from sb3_genrl.envs import get_task
from sb3_genrl.envs.demonstrations.fetch import evaluate_success, replay_success

from benchmarks.fetch_seed import fitted_policy
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED
from sb3_genrl.data.fingerprints import file_fingerprint
from sb3_genrl.genrl import GenRL
from sb3_genrl.genrl.demonstrations import fit_mean_to_demonstrations
from sb3_genrl.genrl.regression import policy_mean
from sb3_genrl.hyperparams import TUNING_GOAL_SEED
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_path, atomic_write_json, atomic_write_text
from sb3_genrl.wrappers import LatentActionWrapper

COLLECTION_SEED = 950000  # reset seeds of the collection states: neither TUNING_GOAL_SEED's nor EVAL_GOAL_SEED's


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--task", default="fetch-push", choices=("fetch-reach", "fetch-push", "fetch-pick-and-place", "fetch-slide")
    )
    parser.add_argument("--generator", type=EXISTING, required=True, help="a VAE of the Fetch recipe")
    parser.add_argument("--data", type=EXISTING, required=True, help="the demonstrations it was trained on")
    parser.add_argument("--states", type=COUNT, default=2000, help="collection states (default 2000)")
    parser.add_argument("--draws", type=COUNT, default=4, help="draws per collection state (default 4)")
    parser.add_argument(
        "--fit-states", type=COUNT, default=300, help="collection states the fitted means are scored on (default 300)"
    )
    parser.add_argument("--tuning-states", type=COUNT, default=200, help="tuning states (default 200)")
    parser.add_argument("--collection-seed", type=SEED, default=COLLECTION_SEED)
    parser.add_argument("--fit-steps", type=COUNT, default=None, help="Adam steps of each fit (default: the entry's)")
    parser.add_argument(
        "--policy",
        type=EXISTING,
        default=None,
        help="a trained GenRL model (genrl_policy.zip) to collect around (default: the fitted start)",
    )
    parser.add_argument(
        "--variants",
        type=variants,
        default=[],
        help="more fits of stage 4 to the nearest solving draws, a JSON list of objects with some of "
        "net_arch, steps, learning_rate, batch_size (the others: the entry's)",
    )
    parser.add_argument(
        "--out",
        type=JSON_OUT,
        default=None,
        help="JSON (default benchmarks/results/fetch_fit_limit_TASK.json; Markdown beside it)",
    )
    args = parser.parse_args(argv)
    if args.fit_states > args.states:
        parser.error(f"--fit-states {args.fit_states} is more than the {args.states} collection states")
    here = os.path.dirname(os.path.abspath(__file__))
    args.out = args.out or os.path.join(here, "results", f"fetch_fit_limit_{args.task}.json")
    return args


def variants(text: str) -> list[dict[str, Any]]:
    """``--variants``: a JSON list of fit settings, each checked."""
    keys = {"net_arch": list, "steps": int, "learning_rate": float, "batch_size": int}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"not JSON: {error}") from None
    if not isinstance(value, list) or not all(isinstance(item, dict) and set(item) <= set(keys) for item in value):
        raise argparse.ArgumentTypeError(f"a list of objects with some of {sorted(keys)}, got {text!r}")
    for item in value:
        for key, kind in keys.items():
            if key in item and not (isinstance(item[key], kind) or kind is float and isinstance(item[key], int)):
                raise argparse.ArgumentTypeError(f"{key} must be a {kind.__name__}, got {item[key]!r}")
        if any(not isinstance(width, int) or width < 1 for width in item.get("net_arch", [])) or any(
            item.get(key, 1) <= 0 for key in ("steps", "learning_rate", "batch_size")
        ):
            raise argparse.ArgumentTypeError(f"positive widths, steps, learning rate and batch size, got {item}")
    return value


def solving_targets(drawn: np.ndarray, solved: np.ndarray, mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each state with a solving draw (in order), the solving draw nearest the mean, and the mean of its solving
    draws.

    :param drawn: draws, ``(states, draws, latent_dim)``
    :param solved: whether each solved its state, ``(states, draws)``
    :param mean: the policy's mean at each state, ``(states, latent_dim)``
    """
    has = solved.any(axis=1)
    distance = np.linalg.norm(drawn - mean[:, None], axis=2) + np.where(solved, 0.0, np.inf)
    nearest = drawn[has, distance[has].argmin(axis=1)]
    average = np.stack([drawn[i][solved[i]].mean(axis=0) for i in np.flatnonzero(has)])
    return nearest.astype(np.float32), average.astype(np.float32)


def anchored_targets(
    has: np.ndarray, nearest: np.ndarray, mean: np.ndarray, solves: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The states that the start's mean solves or some draw solves, and at each the mean where it solves, else the
    nearest solving draw.

    :param has: whether each state has a solving draw, ``(states,)``
    :param nearest: the nearest solving draw of each state that has one, in order, ``(has.sum(), latent_dim)``
    :param mean: the start's mean at each state, ``(states, latent_dim)``
    :param solves: whether the mean solves each state, ``(states,)``
    """
    draw = np.zeros_like(mean)
    draw[has] = nearest
    states = has | solves
    return states, np.where(solves[:, None], mean, draw)[states].astype(np.float32)


def main(argv: list[str] | None = None) -> dict:
    args = arguments(argv)
    th.set_num_threads(1)
    begin = time.perf_counter()
    model, fit, pulls = fitted_policy(args.task, args.generator, args.data, fit_steps=args.fit_steps)
    start = "the fitted start (the demonstrations)"
    if args.policy is not None:  # the collection around a trained policy instead of the fitted start
        model, start = GenRL.load(args.policy, device="cpu", generator=model.generator), f"the policy {args.policy}"
    rows = [{"policy": start, "pairs": len(pulls[1]) if args.policy is None else "", **scored(model, args)}]
    print(rows[-1], flush=True)
    collection, found = collected(model, args)
    rows += replayed_targets(model.generator, found, args)
    rows += fitted_means(found, pulls, fit, args, own_mean(model, found, args))
    result = {
        "benchmark": f"fetch_fit_limit_{args.task}",
        "command": "python -m " + " ".join(["benchmarks.fetch_fit_limit", *(argv if argv is not None else sys.argv[1:])]),
        **provenance(),
        "task": args.task,
        "generator": os.path.abspath(args.generator),
        "data": os.path.abspath(args.data),
        "policy": args.policy and os.path.abspath(args.policy),
        "fit_steps": fit.fit_steps if args.fit_steps is None else args.fit_steps,
        "tuning_states": args.tuning_states,
        "tuning_seed": TUNING_GOAL_SEED,
        "fit_states": args.fit_states,
        "collection_seed": args.collection_seed,
        "collection": collection,
        "rows": rows,
        "seconds": time.perf_counter() - begin,
    }
    write_outputs(result, args)
    return result


def scored(candidate: GenRL, args: argparse.Namespace) -> dict[str, float]:
    """``candidate``'s success on the tuning states and on the first ``--fit-states`` collection states."""
    return {
        "tuning": evaluate_success(candidate, args.task, args.tuning_states, TUNING_GOAL_SEED)["success_rate"],
        "fit_states": evaluate_success(candidate, args.task, args.fit_states, args.collection_seed)["success_rate"],
    }


def collected(model: GenRL, args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any]]:
    """:func:`collect`, kept beside the output (``OUT_collection.npz``, with the settings that made it) and reused by a
    rerun with the same task, generator, start, states, draws and seed."""
    path = os.path.splitext(args.out)[0] + "_collection.npz"
    settings = {
        "task": args.task,
        "generator_fingerprint": file_fingerprint(args.generator),
        "policy_fingerprint": args.policy and file_fingerprint(args.policy),
        "states": args.states,
        "draws": args.draws,
        "collection_seed": args.collection_seed,
        "fit_steps_of_the_start": args.fit_steps,
    }
    if os.path.exists(path):
        with np.load(path) as stored:
            if json.loads(str(stored["settings"])) == settings:
                print(f"the collection of {path} reused", flush=True)
                found = {key: stored[key] for key in ("contexts", "seeds", "has", "nearest", "average")}
                return json.loads(str(stored["collection"])), {**found, "seeds": found["seeds"].tolist()}
        print(f"{path} holds a collection of other settings: collected again", flush=True)
    collection, found = collect(model, args)
    with atomic_path(path) as tmp, open(tmp, "wb") as file:
        np.savez(
            file,
            settings=json.dumps(settings),
            collection=json.dumps(collection),
            **{key: np.asarray(value) for key, value in found.items()},
        )
    return collection, found


def collect(model: GenRL, args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any]]:
    """Stage 2: ``--draws`` draws from the policy's spread around its mean at each collection state, played. Returns
    the collection's summary and what was found: the states' contexts and reset seeds, whether each has a solving
    draw, and its nearest solving draw and mean of solving draws (:func:`solving_targets`)."""
    env = LatentActionWrapper(gym.make(get_task(args.task).env_id), model.generator)
    seeds = [args.collection_seed + i for i in range(args.states)]
    contexts = np.stack([env.reset(seed=seed)[0] for seed in seeds]).astype(np.float32)
    low, high = env.action_space.low, env.action_space.high
    env.close()
    with th.no_grad():
        distribution = model.policy.get_distribution(th.as_tensor(contexts)).distribution
        mean, spread = distribution.mean.numpy(), distribution.stddev.numpy()
    rng = np.random.default_rng(args.collection_seed)
    drawn = np.clip(
        mean[:, None] + spread[:, None] * rng.standard_normal((args.states, args.draws, mean.shape[1])), low, high
    ).astype(np.float32)
    solved = replay_success(
        model.generator, args.task, drawn.reshape(-1, mean.shape[1]), [seed for seed in seeds for _ in range(args.draws)]
    ).reshape(args.states, args.draws)
    has = solved.any(axis=1)
    collection = {
        "states": args.states,
        "draws": args.draws,
        "spread": float(spread.mean()),
        "draw_success": float(solved.mean()),
        "states_with_a_solving_draw": float(has.mean()),
    }
    print(collection, flush=True)
    if not has.any():
        raise SystemExit(
            f"no draw solved any of the {args.states} collection states: nothing to fit the mean to "
            "(more --states or --draws, or a policy that solves some states)"
        )
    nearest, average = solving_targets(drawn, solved, mean)
    return collection, {"contexts": contexts, "seeds": seeds, "has": has, "nearest": nearest, "average": average}


def replayed_targets(generator: Any, found: dict[str, Any], args: argparse.Namespace) -> list[dict[str, Any]]:
    """Stage 3: the targets played again at the first ``--fit-states`` collection states (a state without a solving
    draw counts as unsolved)."""
    rows, first = [], np.flatnonzero(found["has"][: args.fit_states])
    for name in ("nearest", "average"):
        targets = found[name]
        hits = replay_success(generator, args.task, targets[: len(first)], [found["seeds"][i] for i in first])
        label = "nearest solving draw" if name == "nearest" else "mean of the solving draws"
        rows.append(
            {
                "policy": f"each state's {label}, played (no fit)",
                "pairs": len(targets),
                "tuning": None,
                "fit_states": float(hits.sum() / args.fit_states),
            }
        )
        print(rows[-1], flush=True)
    return rows


def own_mean(model: GenRL, found: dict[str, Any], args: argparse.Namespace) -> dict[str, np.ndarray]:
    """The start's mean at every collection state (clipped to the action box) and whether it solves there."""
    low, high = model.action_space.low, model.action_space.high
    with th.no_grad():
        mean = np.clip(policy_mean(model.policy, th.as_tensor(found["contexts"])).numpy(), low, high).astype(np.float32)
    solves = replay_success(model.generator, args.task, mean, found["seeds"])
    print(f"the start's mean solves {solves.mean():.3f} of the {len(solves)} collection states", flush=True)
    return {"mean": mean, "solves": solves}


def fitted_means(
    found: dict[str, Any], pulls: tuple[th.Tensor, th.Tensor], fit: Any, args: argparse.Namespace, start: dict[str, np.ndarray]
) -> list[dict[str, Any]]:
    """Stage 4: the mean fitted from scratch (the entry's fit, or ``--fit-steps``) to the nearest solving draws, to
    those with the demonstrations, to the start's own mean at every state (whether a fit reproduces a mean that
    the network can hold), and to the start's mean where it solves with the nearest solving draw elsewhere; then
    each of ``--variants`` to the nearest solving draws: its residual error and its success."""
    entry = {
        "net_arch": None,
        "steps": fit.fit_steps if args.fit_steps is None else args.fit_steps,
        "learning_rate": fit.learning_rate,
        "batch_size": fit.batch_size,
    }
    pairs = (th.as_tensor(found["contexts"][found["has"]]), th.as_tensor(found["nearest"]))
    with_demonstrations = tuple(th.cat(p) for p in zip(pulls, pairs, strict=True))
    own = (th.as_tensor(found["contexts"]), th.as_tensor(start["mean"]))
    states, targets = anchored_targets(found["has"], found["nearest"], start["mean"], start["solves"])
    kept = (th.as_tensor(found["contexts"][states]), th.as_tensor(targets))
    fits = [
        ("the mean fitted to the nearest solving draws", pairs, entry),
        ("the mean fitted to them and the demonstrations", with_demonstrations, entry),
        ("the mean fitted to the start's own mean (a map the network holds)", own, entry),
        ("the mean fitted to the start's mean where it solves, else the nearest solving draw", kept, entry),
        *(
            (
                "the mean fitted to the nearest solving draws, "
                + ", ".join(f"{key} {value}" for key, value in variant.items()),
                pairs,
                {**entry, **variant},
            )
            for variant in args.variants
        ),
    ]
    rows = []
    for name, (pair_contexts, pair_latents), settings in fits:
        fresh, _, _ = fitted_policy(args.task, args.generator, args.data, fit_steps=0, net_arch=settings["net_arch"])
        fit_mean_to_demonstrations(
            fresh.policy,
            pair_contexts,
            pair_latents,
            steps=settings["steps"],
            learning_rate=settings["learning_rate"],
            batch_size=settings["batch_size"],
        )
        with th.no_grad():
            residual = float((policy_mean(fresh.policy, pairs[0]) - pairs[1]).pow(2).mean())
        rows.append(
            {"policy": name, "pairs": len(pair_latents), **scored(fresh, args), "residual_mse": residual, "fit": settings}
        )
        print(rows[-1], flush=True)
    return rows


def write_outputs(result: dict[str, Any], args: argparse.Namespace) -> None:
    """The JSON and, beside it, its Markdown table."""
    atomic_write_json(args.out, result)
    rows, collection = result["rows"], result["collection"]
    table = markdown_table(
        [
            "policy",
            "pairs",
            f"success, {args.fit_states} collection states",
            f"success, {args.tuning_states} tuning states",
            "residual MSE on the solving draws",
        ],
        [
            [
                r["policy"],
                r["pairs"],
                r["fit_states"],
                "" if r["tuning"] is None else r["tuning"],
                f"{r['residual_mse']:.4f}" if "residual_mse" in r else "",
            ]
            for r in rows
        ],
        align="lrrrr",
    )
    around = "the fitted mean" if args.policy is None else "the policy's mean"
    atomic_write_text(
        os.path.splitext(args.out)[0] + ".md",
        "\n".join(
            [
                f"# What GenRL's mean can hold on {args.task}",
                "",
                f"`{result['command']}`",
                "",
                f"{args.states} collection states x {args.draws} draws from {around}'s spread "
                f"({collection['spread']:.3f}): one draw solves {collection['draw_success']:.3f}, some draw solves "
                f"{collection['states_with_a_solving_draw']:.3f} of the states.",
                "",
                table,
                "",
            ]
        ),
    )
    print(table)


if __name__ == "__main__":
    main()
