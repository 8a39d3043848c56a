#!/usr/bin/env bash
# Rebuild the package's built-in tuning (predictors/tuned.json) of kf, ekf and cv.
# `bench tune` never writes the package's file: this script has it write a file of its own,
# then installs that file here. Development drives only, never an evaluation data set:
# synthetic drives with seeds 1000-1002 for the simulated GPS profiles, the paper's 12
# training routes for native (its 3 held-out routes and KITTI are never used).
# Needs ../shared/data; run it with the environment that has posbench installed active.
set -euo pipefail
cd "$(dirname "$0")/.."
A=../shared/data/aslan
OUT=build/tuned.json  # a file of the script's own (build/ is not tracked)
mkdir -p build
rm -f "$OUT"
DEV=()
for r in aslan-0.5speed-20220308131954 aslan-20220408124005 aslan-20220409115940 \
         aslan-20220413125957 aslan-20220502091737 aslan-20220502092513 aslan-20220504082807 \
         aslan-20220504083146 aslan-20220629142208 aslan-normal-20220104144925 \
         aslan-normal-20220113134616 aslan-normal-20220117144325; do
  DEV+=(--data "$A/$r.pickle")
done
for p in kf ekf cv; do
  for g in none rtk consumer; do
    bench tune "$p" --gps-profile "$g" --calibrate-only --drives 3 --out "$OUT"
  done
  bench tune "$p" --gps-profile native --calibrate-only "${DEV[@]}" --out "$OUT"
done
cp "$OUT" predictors/tuned.json
echo "wrote predictors/tuned.json"
