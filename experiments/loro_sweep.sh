#!/usr/bin/env bash
# Leave-one-recording-out validation of the one recipe (a refiner on top of the device's floor) for
# the devices whose models ship (docs/experiments/loro.md): every
# recording of a device held out in turn, three seeds, `imu-learn fit --loro`.
#
#   IMU_LEARN_DATA=<data root> bash experiments/loro_sweep.sh [WORK [SECONDS]]
#
# WORK (default reports/loro) gets one folder per device (loro.md, loro.json, the folds' profiles and
# runs); SECONDS caps each device's sweep (a rerun continues where it stopped; over a sweep scored
# before the open-loop AOE was a cell of the verdict, the rerun scores the AOE from the saved runs
# without retraining). The training budgets
# are the configs' own with the epochs below (measured on one H100 machine, 16 cores, all devices at
# once: the figures in docs/experiments/loro.md). Without a GPU each run takes about 2-6 min on one core (Blackbird 6 x 200 steps: 108 s of training);
# on a 2-core machine shared with other jobs Blackbird's six runs, 2 at once, took about 8 min each.
set -u
WORK=${1:-reports/loro}
LIMIT=${2:-0}
CLI=${IMU_LEARN_CLI:-imu-learn}
mkdir -p "$WORK"
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 RAYON_NUM_THREADS=1 PYTHONUNBUFFERED=1

sweep() {  # NAME CONFIG JOBS [fit options...]
  local name=$1 config=$2 jobs=$3
  shift 3
  timeout "${LIMIT}" $CLI fit --config "$config" --loro "$WORK/$name" --jobs "$jobs" "$@" >"$WORK/$name.log" 2>&1 &
}
[ "$LIMIT" = 0 ] && LIMIT=1000000
sweep fetch configs/fetch_all.toml 6 --optim.epochs 6
sweep euroc configs/euroc_paper.toml 5 --optim.epochs 8
sweep tumvi configs/tumvi.toml 3 --optim.epochs 6
sweep blackbird configs/blackbird.toml 2 --recordings train val --optim.epochs 6 --loss.w_q 1000 \
  --optim.select_horizons '[10,200]'
wait
for f in "$WORK"/*/loro.md; do echo "== $f"; cat "$f"; done
