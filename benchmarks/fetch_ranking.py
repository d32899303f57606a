"""Can a critic over latent actions pick, among draws from a trained GenRL policy's spread, one that solves more often
than the policy's mean? (The direction of DSRL: a critic that ranks a generative policy's noise.)

1. the collection: ``--states`` initial states (reset seeds from ``--collection-seed``, neither the tuning's nor the
   evaluation's), at each the policy's deterministic latent action and ``--draws`` draws from its spread, played;
2. the tuning states: ``--tuning-states`` initial states (:data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED`), at each
   the deterministic action and ``--candidates - 1`` draws, played: the mean's success and the best of the candidates
   (an oracle that knows which solves);
3. critics ``Q(context, alpha)`` (an MLP on the policy's features of the context and the latent action, a logistic
   regression on success) fitted to the collection, each scored by the success of the candidate it ranks first among
   the first 4, 8 and 16 candidates, and with the mean kept unless the critic gives it less than a threshold.

The held-out evaluation states are never used. The played collection and candidates are kept beside the output
(``OUT_played.npz``) and reused by a rerun of the same settings.

    python -m benchmarks.fetch_ranking --task fetch-push --policy RUN/genrl_policy.zip
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
from sb3_genrl.envs.demonstrations.fetch import replay_success

from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED
from sb3_genrl.data.fingerprints import file_fingerprint
from sb3_genrl.genrl import GenRL
from sb3_genrl.hyperparams import TUNING_GOAL_SEED
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_path, atomic_write_json, atomic_write_text
from sb3_genrl.vec_env import default_threads
from sb3_genrl.wrappers import LatentActionWrapper

COLLECTION_SEED = 950000  # reset seeds of the collection states: neither TUNING_GOAL_SEED's nor EVAL_GOAL_SEED's
CRITICS = (((256, 256), 4000), ((256, 256, 256), 8000), ((512, 512), 8000))  # hidden layers, Adam steps
THRESHOLDS = (0.5, 0.8)  # the mean is kept where the critic gives it at least this


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--task", default="fetch-push", choices=("fetch-reach", "fetch-push", "fetch-pick-and-place", "fetch-slide")
    )
    parser.add_argument("--policy", type=EXISTING, required=True, help="a trained GenRL model (genrl_policy.zip)")
    parser.add_argument("--states", type=COUNT, default=1000, help="collection states (default 1000)")
    parser.add_argument("--draws", type=COUNT, default=5, help="draws per collection state (default 5)")
    parser.add_argument("--tuning-states", type=COUNT, default=200, help="tuning states (default 200)")
    parser.add_argument("--candidates", type=COUNT, default=16, help="candidates per tuning state, the mean first")
    parser.add_argument("--collection-seed", type=SEED, default=COLLECTION_SEED)
    parser.add_argument("--out", type=JSON_OUT, default=None, help="JSON (default results/fetch_ranking_TASK.json)")
    args = parser.parse_args(argv)
    if args.candidates < 16:
        parser.error("--candidates must be at least 16 (the critics pick among the first 4, 8 and 16)")
    here = os.path.dirname(os.path.abspath(__file__))
    args.out = args.out or os.path.join(here, "results", f"fetch_ranking_{args.task}.json")
    return args


def ranked_first(scores: np.ndarray, solved: np.ndarray, k: int, keep_mean: float | None = None) -> float:
    """The share of states solved by the candidate with the highest score among each state's first ``k`` (the mean
    is candidate 0); with ``keep_mean``, the mean wherever its own score is at least that.

    :param scores: the critic's score of each candidate, ``(states, candidates)``
    :param solved: whether each candidate solves its state, ``(states, candidates)``
    """
    pick = scores[:, :k].argmax(axis=1)
    if keep_mean is not None:
        pick = np.where(scores[:, 0] >= keep_mean, 0, pick)
    return float(solved[np.arange(len(solved)), pick].mean())


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = arguments(argv)
    th.set_num_threads(1)
    begin = time.perf_counter()
    model = GenRL.load(args.policy, device="cpu")
    played = played_candidates(model, args)
    collection, tuning = played["collection"], played["tuning"]
    rows = [
        {"choice": "the policy's mean (deterministic action)", "success": float(tuning["solved"][:, 0].mean())},
        {"choice": "one draw from the spread", "success": float(tuning["solved"][:, 1:].mean())},
        *(
            {"choice": f"the best of {k} candidates (an oracle)", "success": float(tuning["solved"][:, :k].any(1).mean())}
            for k in (4, 8, 16)
        ),
    ]
    for hidden, steps in CRITICS:
        scores = critic_scores(model, collection, tuning, hidden, steps)
        name = f"critic {list(hidden)}, {steps} steps"
        rows += [
            {"choice": f"{name}: its first of {k}", "success": ranked_first(scores, tuning["solved"], k)} for k in (4, 8, 16)
        ]
        rows += [
            {
                "choice": f"{name}: the mean unless it scores below {threshold}, else its first of 16",
                "success": ranked_first(scores, tuning["solved"], 16, keep_mean=threshold),
            }
            for threshold in THRESHOLDS
        ]
        print(rows[-5:], flush=True)
    result = {
        "benchmark": f"fetch_ranking_{args.task}",
        "command": "python -m " + " ".join(["benchmarks.fetch_ranking", *(argv if argv is not None else sys.argv[1:])]),
        **provenance(),
        "task": args.task,
        "policy": os.path.abspath(args.policy),
        "collection_seed": args.collection_seed,
        "tuning_seed": TUNING_GOAL_SEED,
        "collection": {"states": args.states, "draws": args.draws, "mean_success": float(collection["solved"][:, 0].mean())},
        "tuning_states": args.tuning_states,
        "candidates": args.candidates,
        "rows": rows,
        "seconds": time.perf_counter() - begin,
    }
    atomic_write_json(args.out, result)
    table = markdown_table(
        ["choice", "success on the tuning states"], [[row["choice"], f"{row['success']:.3f}"] for row in rows]
    )
    atomic_write_text(
        os.path.splitext(args.out)[0] + ".md",
        f"# A critic ranking a GenRL policy's draws on {args.task}\n\n`{result['command']}`\n\n{table}\n",
    )
    print(table)
    return result


def played_candidates(model: GenRL, args: argparse.Namespace) -> dict[str, dict[str, np.ndarray]]:
    """Stages 1 and 2 (contexts, candidates, whether each solves), kept in ``OUT_played.npz`` with the settings that
    made them and reused by a rerun of the same."""
    path = os.path.splitext(args.out)[0] + "_played.npz"
    settings = {
        key: getattr(args, key) for key in ("task", "states", "draws", "tuning_states", "candidates", "collection_seed")
    } | {"policy_fingerprint": file_fingerprint(args.policy)}
    if os.path.exists(path):
        with np.load(path) as stored:
            if json.loads(str(stored["settings"])) == settings:
                print(f"the played candidates of {path} reused", flush=True)
                return {
                    part: {key: stored[f"{part}_{key}"] for key in ("contexts", "latents", "solved")}
                    for part in ("collection", "tuning")
                }
        print(f"{path} holds candidates of other settings: played again", flush=True)
    played = {
        "collection": candidates(model, args.task, args.collection_seed, args.states, args.draws + 1),
        "tuning": candidates(model, args.task, TUNING_GOAL_SEED, args.tuning_states, args.candidates),
    }
    with atomic_path(path) as tmp, open(tmp, "wb") as file:
        np.savez(
            file,
            settings=json.dumps(settings),
            **{f"{part}_{key}": value for part, arrays in played.items() for key, value in arrays.items()},
        )
    return played


def candidates(model: GenRL, task: str, seed: int, states: int, count: int) -> dict[str, np.ndarray]:
    """At ``states`` initial states (reset seeds ``seed, seed + 1, ...``) the policy's deterministic latent action and
    ``count - 1`` draws from its spread (clipped to the latent box), each played open loop."""
    env = LatentActionWrapper(gym.make(get_task(task).env_id), model.generator)
    contexts = np.stack([env.reset(seed=seed + i)[0] for i in range(states)]).astype(np.float32)
    low, high = env.action_space.low, env.action_space.high
    env.close()
    with th.no_grad():
        distribution = model.policy.get_distribution(th.as_tensor(contexts)).distribution
        mean, spread = distribution.mean.numpy(), distribution.stddev.numpy()
    noise = np.random.default_rng(seed).standard_normal((states, count - 1, mean.shape[1]))
    latents = np.concatenate(
        [model.predict(contexts, deterministic=True)[0][:, None], mean[:, None] + spread[:, None] * noise], 1
    )
    latents = np.clip(latents, low, high).astype(np.float32)
    seeds = [seed + i for i in range(states) for _ in range(count)]
    began = time.perf_counter()
    solved = replay_success(model.generator, task, latents.reshape(states * count, -1), seeds, n_threads=default_threads())
    print(f"{states * count} episodes played in {time.perf_counter() - began:.0f} s", flush=True)
    return {"contexts": contexts, "latents": latents, "solved": solved.reshape(states, count)}


def critic_scores(
    model: GenRL, collection: dict[str, np.ndarray], tuning: dict[str, np.ndarray], hidden: tuple[int, ...], steps: int
) -> np.ndarray:
    """A critic fitted to the collection's (context, latent action, success), by logistic regression with Adam
    (minibatches of 256, seed 0): its probability of success for each tuning candidate."""

    def inputs(part: dict[str, np.ndarray]) -> th.Tensor:
        with th.no_grad():
            features = model.policy.extract_features(th.as_tensor(part["contexts"]), model.policy.pi_features_extractor)
        latents = th.as_tensor(part["latents"])
        return th.cat([features[:, None].expand(-1, latents.shape[1], -1), latents], dim=-1)

    th.manual_seed(0)
    x = inputs(collection).reshape(-1, inputs(collection).shape[-1])
    y = th.as_tensor(collection["solved"].reshape(-1), dtype=th.float32)
    sizes, layers = [x.shape[1], *hidden], []
    for size_in, size_out in zip(sizes[:-1], sizes[1:], strict=True):
        layers += [th.nn.Linear(size_in, size_out), th.nn.ReLU()]
    critic = th.nn.Sequential(*layers, th.nn.Linear(sizes[-1], 1))
    optimizer = th.optim.Adam(critic.parameters(), lr=1e-3)
    for _ in range(steps):
        rows = th.randint(len(y), (256,))
        loss = th.nn.functional.binary_cross_entropy_with_logits(critic(x[rows]).squeeze(-1), y[rows])
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    with th.no_grad():
        return th.sigmoid(critic(inputs(tuning)).squeeze(-1)).numpy()


if __name__ == "__main__":
    main()
