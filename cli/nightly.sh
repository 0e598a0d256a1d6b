#!/usr/bin/env bash
# Nightly recipe: every pass file of the day through the chain the config names
# (ingest -> smooth, and the multi-pass estimate per window when configured).
#
#   cli/nightly.sh CONFIG.toml LOGDIR [BATCH OPTION...]
#
# crontab line (every night at 03:30; silent when all went well, so cron mails only problems;
# cron's PATH is short, hence the full path of the virtual environment's trackproc):
#   30 3 * * *  TRACKPROC=/opt/trackproc/.venv/bin/trackproc /opt/trackproc/cli/nightly.sh /etc/trackproc/nightly.toml /var/log/trackproc
#
# - The log of each night is appended to LOGDIR/batch-YYYY-MM-DD.log (UTC date), with timestamps.
# - Exit status is trackproc batch's: 0 all done; 3 partial failure (each failed input is in the
#   log and in OUTPUT/summary.csv with its reason); 1 all failed, or another run still holds the
#   output directory's lock (set wait = true in [batch] to wait for it instead); 2 usage or
#   configuration error. Anything but 0 also prints one line on stderr, which cron mails.
# - Running it again is safe and cheap: results up to date with their input, the config and the
#   trackproc version are skipped, so a night that failed can simply be re-run (add --force to
#   redo everything, --retry-failed to retry inputs that failed on their data).
set -uo pipefail
if [ $# -lt 2 ]; then
    echo "usage: $0 CONFIG.toml LOGDIR [BATCH OPTION...]" >&2
    exit 2
fi
config=$1
logdir=$2
shift 2
trackproc=${TRACKPROC:-trackproc}
if ! mkdir -p "$logdir"; then
    echo "$(date -u +%FT%TZ) trackproc nightly: cannot create the log directory $logdir" >&2
    exit 2
fi
log="$logdir/batch-$(date -u +%F).log"

"$trackproc" batch "$config" --log "$log" "$@"
status=$?

stamp=$(date -u +%FT%TZ)
case $status in
    0) ;;
    3) echo "$stamp trackproc nightly: partial failure (exit 3): some inputs failed; reasons in $log and in the output directory's summary.csv" >&2 ;;
    1) echo "$stamp trackproc nightly: nothing succeeded, or another run holds the lock (exit 1); see $log" >&2 ;;
    2) echo "$stamp trackproc nightly: usage or configuration error (exit 2), nothing was done" >&2 ;;
    *) echo "$stamp trackproc nightly: stopped (exit $status); see $log" >&2 ;;
esac
exit $status
