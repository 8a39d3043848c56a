#!/usr/bin/env bash
# Regenerate every reference report in reports/ (needs ../shared/data and ../shared/models).
# Each folder is exactly what its command wrote (report.md names the command).
# Run it with the environment that has posbench installed active (bench on PATH).
set -euo pipefail
cd "$(dirname "$0")/.."
S=../shared
bench run --out reports/synthetic
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,hybrid --data $S/data/kitti_raw --out reports/kitti
# the learned predictors against the filters on independent truth at the other GPS profiles
bench run --predictors cv,kf,ekf,lstm,hybrid --data $S/data/kitti_raw --gps-profile none \
  --drive-plots 0 --out reports/kitti-none
bench run --predictors cv,kf,ekf,lstm,hybrid --data $S/data/kitti_raw --gps-profile consumer \
  --drive-plots 0 --out reports/kitti-consumer
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,hybrid,lstm-authors \
  --model lstm-authors=$S/models/authors/gps_interpolation_model3.onnx \
  --data $S/data/aslan --data $S/data/kitti_raw --data $S/data/comma2k19 --out reports/all-data
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,hybrid --dropouts outages \
  --data $S/data/aslan --data $S/data/kitti_raw --data $S/data/comma2k19 --out reports/outages
# outages as the field reports them: the error 1-60 s into an outage, in metres and as % of the
# distance travelled since the last fix (KITTI at rtk, evaluation only)
bench run --predictors cv,kf,ekf,lstm,hybrid --data $S/data/kitti_raw --gps-profile rtk \
  --dropouts outage-lengths --drive-plots 0 --out reports/kitti-outage-lengths
bench latency --json > reports/latency.json
# bench run's wall time and peak memory (RSS) against drive hours (docs: Speed): the corpus at
# 4, 16 and 64 h, one 8 h drive at 1 Hz fixes, one 2 h drive at 10 Hz fixes and 100 Hz IMU,
# and the 16 h corpus on a local Ray of 2 workers (skipped, said, without Ray)
python reports/scaling.py --cases corpus,long-1hz,long-10hz,ray --hours 4 16 64 \
  --long-1hz-hours 8 --long-10hz-hours 2 --ray-hours 16
# the outlier gate's effect on the paper's routes: the same run with the gate off
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,lstm-authors \
  --model lstm-authors=$S/models/authors/gps_interpolation_model3.onnx \
  --data $S/data/aslan --no-gate --out reports/aslan-no-gate
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,lstm-authors \
  --model lstm-authors=$S/models/authors/gps_interpolation_model3.onnx \
  --data $S/data/aslan --out reports/aslan-gate
