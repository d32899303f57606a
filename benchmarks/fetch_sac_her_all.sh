#!/bin/bash
# The package's SAC+HER part of the Fetch benchmark (benchmarks/fetch_sac_her.py): every task with and without the
# demonstrations, 3 seeds each, in LANES parallel lanes (default 2, one core each), each lane running its share of the
# runs in turn. Rerun the same command to resume: a finished seed is kept, an unfinished one continues from its last
# checkpoint (at most 250 episodes back). JSON: runs/fetch_sac_her/fetch_sac_her_TASK_VARIANT.json, one per task and
# variant, copied into benchmarks/results/ when published; each lane's log: runs/fetch_sac_her/lane_K.log.
#
#   bash benchmarks/fetch_sac_her_all.sh [TASK:VARIANT ...]     # e.g. fetch-slide:demos fetch-slide:none
cd "$(dirname "$0")/.."
export MUJOCO_GL=egl OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
lanes=${LANES:-2}
runs=("$@")
[ ${#runs[@]} -gt 0 ] || runs=(fetch-reach:demos fetch-reach:none fetch-push:demos fetch-push:none
                               fetch-pick-and-place:demos fetch-pick-and-place:none fetch-slide:demos fetch-slide:none)
mkdir -p runs/fetch_sac_her
lane() {  # lane K runs every LANES-th (task, variant), starting at the K-th
  local k=$1 i
  for ((i = k; i < ${#runs[@]}; i += lanes)); do
    local task=${runs[i]%%:*} variant=${runs[i]##*:}
    echo "=== $task $variant $(date -u)"
    .venv/bin/python -m benchmarks.fetch_sac_her --task "$task" --variant "$variant" --seeds 0 1 2 \
      || echo "=== $task $variant failed (exit $?)"
  done
  echo "=== lane $k done $(date -u)"
}
for ((k = 0; k < lanes; k++)); do
  lane "$k" > "runs/fetch_sac_her/lane_$k.log" 2>&1 &
done
wait
