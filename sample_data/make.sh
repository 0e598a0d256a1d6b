#!/usr/bin/env bash
# Regenerates every file of sample_data/ from stations.csv, truth.json and stale.json
# (hand-written inputs) with trackproc itself. Deterministic: fixed seeds.
set -euo pipefail
cd "$(dirname "$0")"

# 1. A single-station Doppler pass (CPH, S-band one-way), as a station would write it: wide CSV in Hz.
head -n 2 stations.csv > .cph.csv
trackproc simulate --state truth.json --stations .cph.csv --start 2026-03-20T09:24:00Z \
    --duration 720 --step 1 --kinds doppler --carrier-hz 2.2e9 --sigma-doppler-hz 0.5 \
    --freq-offset-hz 150 --freq-drift-hz-s 0.02 --seed 4 --wide -o doppler_pass.csv
rm -f .cph.csv

# 2. An elevation pass (ZHY), wide CSV in degrees.
trackproc simulate --state truth.json --stations stations.csv --start 2026-03-20T09:24:00Z \
    --duration 900 --step 2 --kinds elevation,azimuth --sigma-angle-deg 0.01 --seed 3 --wide \
    -o .angles.csv
{ head -n 1 .angles.csv; grep ',ZHY,' .angles.csv; } > elevation_pass.csv
rm -f .angles.csv

# 3. Several stations, several passes, range biases: the canonical Parquet form.
trackproc simulate --state truth.json --stations stations.csv --duration 43200 --step 10 \
    --kinds range,range_rate,elevation,azimuth --range-bias CPH=120 --range-bias ZHY=-80 \
    --range-bias KIR=45 --sigma-range-m 5 --sigma-range-rate-m-s 0.005 --seed 2 \
    --truth truth_at_start.json -o multistation.parquet
