#!/bin/bash
# rl-zoo3's TQC+HER on a Fetch task through rl-zoo3's own entry point (python -m rl_zoo3.train) with its stock
# hyperparameters (benchmarks/tqc_fetch.yml), 1 seed, in segments of SEGMENT_STEPS environment steps, so that it resumes
# after any stop with the same command:
#
#   bash benchmarks/tqc_fetch.sh FetchPush-v4 [LOG_FOLDER] [SEED]     # default runs/tqc, seed 0
#   TOTAL_STEPS=25000 THREADS=2 bash benchmarks/tqc_fetch.sh ...        # stop at 500 episodes; 2 torch threads
#
# rl-zoo3 saves the replay buffer (--save-replay-buffer) only when a training run ends (or on Ctrl-C), not with its
# --save-freq checkpoints, so each segment is one rl-zoo3 run of SEGMENT_STEPS steps (-n, default 50 episodes), and
# the next one continues it with -i from the last segment that saved both its model and its replay buffer; a segment
# stopped part-way is played again. Each segment's rl-zoo3 run counts its timesteps from 0, so a continued segment is
# given learning_starts 0 (-params): the stock 100 random steps belong to the start of the run only, and the buffer
# is already filled. Segment k runs with rl-zoo3's --seed SEED * 100000 + k: with one seed for all, every segment's env
# would draw the same goals again. ENV_seedS_segments.csv lists the segments done, with the environment steps in all.
# --gym-packages sb3_genrl.envs registers the Fetch ids whose entry points apply the MuJoCo 4.0 fix
# (sb3_genrl.envs.fetch_mujoco) and make Gymnasium-Robotics' unmodified envs. Each segment ends with rl-zoo3's
# evaluation of EVAL_EPISODES = 50 episodes (its evaluations.npz holds their successes).
set -euo pipefail
ENV_ID=${1:?usage: tqc_fetch.sh ENV_ID [LOG_FOLDER] [SEED]}
LOGS=${2:-runs/tqc}
SEED=${3:-0}
SEGMENT_STEPS=${SEGMENT_STEPS:-2500}  # 50 episodes of 50 steps
cd "$(dirname "$0")/.."
# the entry's own budget (n_timesteps) unless TOTAL_STEPS is given
TOTAL_STEPS=${TOTAL_STEPS:-$(.venv/bin/python -c "import sys, yaml; print(int(yaml.safe_load(open('benchmarks/tqc_fetch.yml'))[sys.argv[1]]['n_timesteps']))" "$ENV_ID")}
EVAL_EPISODES=${EVAL_EPISODES:-50}
THREADS=${THREADS:-1}  # torch threads of each segment (rl-zoo3's --num-threads)
export MUJOCO_GL=egl OMP_NUM_THREADS=$THREADS MKL_NUM_THREADS=$THREADS
mkdir -p "$LOGS"
LIST="$LOGS/${ENV_ID}_seed${SEED}_segments.csv"
[ -f "$LIST" ] || echo "segment,folder,env_steps_total" > "$LIST"
while true; do
  segment=$(( $(wc -l < "$LIST") ))  # this segment's number (the list has a header)
  done_steps=$(tail -n +2 "$LIST" | tail -1 | cut -d, -f3)
  done_steps=${done_steps:-0}
  if [ "$done_steps" -ge "$TOTAL_STEPS" ]; then echo "$ENV_ID: $done_steps steps done"; break; fi
  last=$(tail -n +2 "$LIST" | tail -1 | cut -d, -f2)
  resume=()
  if [ -n "$last" ]; then resume=(-i "$last/$ENV_ID.zip" -params learning_starts:0); fi
  before=$(ls -d "$LOGS/tqc/${ENV_ID}_"* 2>/dev/null | sort -V | tail -1 || true)
  echo "=== $ENV_ID segment $segment from ${last:-scratch} $(date -u)"
  .venv/bin/python -m rl_zoo3.train --algo tqc --env "$ENV_ID" -conf benchmarks/tqc_fetch.yml \
    --gym-packages sb3_genrl.envs --seed $(( SEED * 100000 + segment )) --num-threads "$THREADS" -f "$LOGS" -n "$SEGMENT_STEPS" \
    --save-freq "$SEGMENT_STEPS" --save-replay-buffer --eval-freq "$SEGMENT_STEPS" --eval-episodes "$EVAL_EPISODES" "${resume[@]}"
  folder=$(ls -d "$LOGS/tqc/${ENV_ID}_"* | sort -V | tail -1)
  if [ "$folder" = "$before" ] || [ ! -f "$folder/$ENV_ID.zip" ] || [ ! -f "$folder/replay_buffer.pkl" ]; then
    echo "segment did not save its model and replay buffer in $folder" >&2; exit 1
  fi
  echo "$segment,$folder,$(( done_steps + SEGMENT_STEPS ))" >> "$LIST"
  if [ -n "$last" ]; then rm -f "$last/replay_buffer.pkl" "$last"/rl_model_*_steps.zip; fi  # the buffer: 270 MB
done
