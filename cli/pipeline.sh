#!/usr/bin/env bash
# The main job on the bundled sample data, by files and by pipes.
#   cli/pipeline.sh [OUTDIR]      (default: ./trackproc-out)
# Every step is a trackproc command; data flow through files or stdout/stdin, logs go to stderr.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
data="$here/../sample_data"
out="${1:-trackproc-out}"
mkdir -p "$out"

echo "== 1. ingest a station's raw Doppler CSV (Hz) into the canonical pass file" >&2
trackproc ingest "$data/doppler_pass.csv" --stations "$data/stations.csv" \
    --carrier-hz 2.2e9 --mode one-way -o "$out/pass.parquet"
trackproc info "$out/pass.parquet"

echo "== 2. smooth it (seed 004 eq. 1): TCA and carrier at closest approach" >&2
trackproc smooth "$out/pass.parquet" --summary "$out/smooth.json" -o "$out/smoothed.parquet"

echo "== 3. the same chain through pipes" >&2
cat "$data/doppler_pass.csv" \
    | trackproc ingest - --stations "$data/stations.csv" --carrier-hz 2.2e9 --mode one-way \
    | trackproc smooth - --summary "$out/smooth_piped.json" > "$out/smoothed_piped.parquet"

echo "== 4. refine the stale state from that one pass (seed 004): what it sees, what it cannot" >&2
trackproc refine "$out/smoothed.parquet" --initial "$data/stale.json" --doppler-bias offset+drift \
    --output-epoch stale --residuals "$out/refine_residuals.csv" -o "$out/refined.json"

echo "== 5. simulate -> ingest -> info, multi-station with range biases" >&2
trackproc simulate --state "$data/truth.json" --stations "$data/stations.csv" \
    --duration 21600 --step 10 --kinds range,range_rate,elevation,azimuth \
    --range-bias CPH=120 --seed 7 --truth "$out/truth_at_start.json" \
    | trackproc ingest - | trackproc info -

echo "== 6. elevation-only pass and the multi-station set shipped with the project" >&2
trackproc ingest "$data/elevation_pass.csv" --stations "$data/stations.csv" -o "$out/elevation.parquet"
trackproc info "$out/elevation.parquet" --json > "$out/elevation_info.json"
trackproc info "$data/multistation.parquet"
echo "== 7. estimate the orbit and the three range biases from the refined state (seed 002)" >&2
trackproc estimate "$data/multistation.parquet" --initial "$out/refined.json" --apriori-initial \
    --range-bias --opm "$out/solution.opm" --residuals "$out/residuals.csv" -o "$out/solution.json"

echo "== 8. how good is the prediction a day ahead? (seed 000) and the ephemeris as CCSDS OEM" >&2
trackproc accuracy "$out/solution.json" --span 86400 --step 3600 --format csv -o "$out/accuracy.csv"
trackproc propagate "$out/solution.json" --span 86400 --step 600 --format oem -o "$out/solution.oem"

echo "== 9. elevation-only sensor requirement, beside the paper's Table 2 (seed 003)" >&2
trackproc requirements --format md --compare-paper -o "$out/requirements.md"
echo "outputs in $out" >&2
