#!/usr/bin/env bash
# Regenerate every reference report in reports/ (needs ../shared/data and ../shared/models).
# Each folder is exactly what its command wrote (report.md names the command).
# Run it with the environment that has posbench installed active (bench on PATH).
set -euo pipefail
cd "$(dirname "$0")/.."
S=../shared
bench run --out reports/synthetic
bench run --predictors cv,poly,kf,kf-paper,ekf --data $S/data/kitti_raw --out reports/kitti
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,lstm-authors \
  --model lstm-authors=$S/models/authors/gps_interpolation_model3.onnx \
  --data $S/data/aslan $S/data/kitti_raw $S/data/comma2k19 --out reports/all-data
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm --dropouts outages \
  --data $S/data/aslan $S/data/kitti_raw $S/data/comma2k19 --out reports/outages
bench latency --json > reports/latency.json
# the outlier gate's effect on the paper's routes: the same run with the gate off
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,lstm-authors \
  --model lstm-authors=$S/models/authors/gps_interpolation_model3.onnx \
  --data $S/data/aslan --no-gate --out reports/aslan-no-gate
bench run --predictors cv,poly,kf,kf-paper,ekf,lstm,lstm-authors \
  --model lstm-authors=$S/models/authors/gps_interpolation_model3.onnx \
  --data $S/data/aslan --out reports/aslan-gate
