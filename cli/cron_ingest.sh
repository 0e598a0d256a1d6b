#!/usr/bin/env bash
# Cron example: ingest and smooth every new raw pass CSV dropped into an inbox directory.
#
#   cli/cron_ingest.sh INBOX OUTBOX STATIONS.csv [CARRIER_HZ]
#
# crontab line (every night at 02:15, logs appended to a file, nothing on a terminal):
#   15 2 * * *  cd /opt/trackproc && cli/cron_ingest.sh /data/inbox /data/passes /data/stations.csv 2.2e9 >> /var/log/trackproc.log 2>&1
#
# One bad file never stops the others: it is reported and the run ends with exit 3 (partial
# failure); 0 when all succeeded, 1 when all failed, 2 on usage errors. A lock (flock) keeps two
# overlapping runs apart. A file is done when its smoothed output is newer than the input.
set -uo pipefail
if [ $# -lt 3 ]; then echo "usage: $0 INBOX OUTBOX STATIONS.csv [CARRIER_HZ]" >&2; exit 2; fi
inbox=$1; outbox=$2; stations=$3; carrier=${4:-2.2e9}
mkdir -p "$outbox"
exec 9>"$outbox/.trackproc.lock"
if ! flock -n 9; then echo "$(date -u +%FT%TZ) another run holds $outbox/.trackproc.lock; skipping" >&2; exit 0; fi

ok=0; failed=0
shopt -s nullglob
for raw in "$inbox"/*.csv; do
    name=$(basename "$raw" .csv)
    done_file="$outbox/$name.smoothed.parquet"
    [ "$done_file" -nt "$raw" ] && continue
    if trackproc --quiet ingest "$raw" --stations "$stations" --carrier-hz "$carrier" --mode one-way \
            -o "$outbox/$name.parquet" \
       && trackproc --quiet smooth "$outbox/$name.parquet" --summary "$outbox/$name.smooth.json" -o "$done_file"; then
        ok=$((ok + 1))
    else
        echo "$(date -u +%FT%TZ) FAILED $raw (exit $?)" >&2
        failed=$((failed + 1))
    fi
done
echo "$(date -u +%FT%TZ) done: $ok ok, $failed failed" >&2
if [ "$failed" -eq 0 ]; then exit 0; elif [ "$ok" -eq 0 ]; then exit 1; else exit 3; fi
