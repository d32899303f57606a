#!/bin/bash
# GenRL's part of the Fetch benchmark (benchmarks/fetch.py) on the given Fetch tasks in turn (default: all four),
# each with its entry in hyperparams/genrl.yml; rerun the same command to resume. JSON: runs/fetch/fetch_TASK.json,
# copied into benchmarks/results/ when a task is published. A task whose JSON holds runs of other GenRL settings
# starts its runs again (--new-runs) and keeps its demonstrations, generator and their measures.
#
#   bash benchmarks/fetch_all.sh [TASK ...]
cd "$(dirname "$0")/.."
export MUJOCO_GL=egl OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
tasks=("$@")
[ ${#tasks[@]} -gt 0 ] || tasks=(fetch-push fetch-reach fetch-pick-and-place fetch-slide)
for task in "${tasks[@]}"; do
  echo "=== $task $(date -u)"
  .venv/bin/python -m benchmarks.fetch --task "$task" --out "runs/fetch/fetch_$task.json" --new-runs \
    || echo "=== $task failed (exit $?)"
done
echo "=== done $(date -u)"
