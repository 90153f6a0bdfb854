#!/usr/bin/env bash
# m7_check.sh: builds and runs the Cortex-M7 benchmark (bench/m7) under m7count (QEMU
# mps2-an500, exact instruction counts) and compares every region with bench/m7/baseline.txt.
#
# usage: scripts/m7_check.sh [--update]
#   --update   rewrite bench/m7/baseline.txt with the counts of this run (commit it)
# environment:
#   M7_TOLERANCE_PCT   allowed growth per region, percent (default 10)
#   M7_MIN_INSNS       regions below this many instructions (baseline and now) are not judged
#                      (default 10000)
#   M7COUNT            path of m7count.sh (default: shared/tools/m7count next to the repo;
#                      install its QEMU and plugin once with its setup.sh, as root)
#
# Fails (exit 1) when a region grew by more than the tolerance, when a baseline region is
# missing or a region has no baseline, or when the benchmark itself failed (build error, a
# typical frame whose detections differ from its markers, QEMU error). Regions that got
# cheaper by more than the tolerance pass with a hint to update the baseline: the counts are
# exact and repeatable, so any change comes from the code (or the toolchain), not from noise.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
readonly BENCH=bench/m7
readonly BASELINE="$BENCH/baseline.txt"
readonly TOLERANCE="${M7_TOLERANCE_PCT:-10}"
# Regions this small (a stage with nothing to do, e.g. pose on a frame without markers) are
# reported but never judged: a few instructions more would be a large percentage.
readonly MIN_INSNS="${M7_MIN_INSNS:-10000}"

update=0
case "${1:-}" in
    --update) update=1 ;;
    "") ;;
    *)
        sed -n '2,10p' "$0"
        exit 2
        ;;
esac

log=$(mktemp)
counts=$(mktemp)
trap 'rm -f "$log" "$counts"' EXIT

# Build and run (the runner is bench/m7/run-m7count.sh). CARGO_TERM_QUIET keeps cargo's
# progress out of the log; the guest's output and the counts are what we parse.
echo "m7_check: building and running ${BENCH} (cargo run --release)"
rc=0
(cd "$BENCH" && cargo run --release) >"$log" 2>&1 || rc=$?
if [ "$rc" -ne 0 ]; then
    cat "$log"
    echo "m7_check: FAILED: the benchmark exited with status ${rc} (see the output above)" >&2
    exit 1
fi

# "<frame>: <stage>" label lines, each followed by "m7count: region K insns N".
awk '
    /^[a-z0-9][a-z0-9-]*: [a-z0-9][a-z0-9-]*$/ { label = $1 $2; next }
    /^m7count: region [0-9]+ insns [0-9]+$/ {
        if (label == "") { print "unlabelled region " $3 > "/dev/stderr"; exit 1 }
        print label, $5
        label = ""
    }
' "$log" >"$counts"
if [ ! -s "$counts" ]; then
    cat "$log"
    echo "m7_check: FAILED: no counted regions in the output (markers missing?)" >&2
    exit 1
fi
# The guest's own lines (detections, stack depths), for the CI log.
grep -E '^(m7bench|[a-z0-9-]+: |  )' "$log" | grep -v '^m7count' || true
echo

# pixels_of LABEL: pixels of the frame named by the label's resolution prefix.
pixels_of() {
    case "$1" in
        qvga-*) echo 76800 ;;
        vga-*) echo 307200 ;;
        *) echo 0 ;;
    esac
}

if [ "$update" -eq 1 ]; then
    {
        echo "# Cortex-M7 instructions per benchmark region (bench/m7 on QEMU mps2-an500, m7count)."
        echo "# Written by scripts/m7_check.sh --update; CI fails when a region grows by more than"
        echo "# ${TOLERANCE}%. Counts are exact: rewrite this file whenever a change moves them."
        echo "# toolchain: $(rustc --version)"
        echo "# region insns"
        cat "$counts"
    } >"$BASELINE"
    echo "m7_check: wrote ${BASELINE} ($(wc -l <"$counts") regions)"
fi

if [ ! -f "$BASELINE" ]; then
    echo "m7_check: FAILED: no ${BASELINE}; run scripts/m7_check.sh --update and commit it" >&2
    exit 1
fi

toolchain=$(sed -n 's/^# toolchain: //p' "$BASELINE")
if [ -n "$toolchain" ] && [ "$toolchain" != "$(rustc --version)" ]; then
    echo "m7_check: note: the baseline was measured with ${toolchain}, this is $(rustc --version);"
    echo "  a compiler upgrade alone can move the counts (update the baseline in its own commit)"
fi

# Compare. Columns: region, baseline, now, change, instructions per pixel, ms at 480 MHz
# (CPI 1; QEMU models no caches or wait states, so this is a lower bound on real time).
status=0
printf '%-28s %12s %12s %8s %8s %9s\n' region baseline now change insn/px ms@480MHz
while read -r region now; do
    base=$(awk -v r="$region" '$1 == r { print $2 }' "$BASELINE")
    px=$(pixels_of "$region")
    per_px=$(awk -v n="$now" -v p="$px" 'BEGIN { if (p > 0) printf "%.1f", n / p; else print "-" }')
    ms=$(awk -v n="$now" 'BEGIN { printf "%.2f", n / 480e3 }')
    if [ -z "$base" ]; then
        printf '%-28s %12s %12d %8s %8s %9s  NEW: not in the baseline\n' "$region" - "$now" - "$per_px" "$ms"
        status=1
        continue
    fi
    verdict=$(awk -v n="$now" -v b="$base" -v t="$TOLERANCE" -v m="$MIN_INSNS" 'BEGIN {
        c = (b > 0) ? 100 * (n - b) / b : 0
        if (n < m && b < m) v = "";
        else if (c > t) v = "REGRESSION"; else if (c < -t) v = "improved"; else v = "";
        printf "%+.1f%% %s", c, v }')
    change=${verdict%% *}
    note=${verdict#* }
    printf '%-28s %12d %12d %8s %8s %9s  %s\n' "$region" "$base" "$now" "$change" "$per_px" "$ms" "$note"
    case "$note" in
        REGRESSION) status=1 ;;
        improved) improved=1 ;;
    esac
done <"$counts"

# Baseline regions the run did not produce.
while read -r region _; do
    case "$region" in '#'* | '') continue ;; esac
    if ! awk -v r="$region" '$1 == r { found = 1 } END { exit !found }' "$counts"; then
        printf '%-28s  MISSING: in the baseline but not measured\n' "$region"
        status=1
    fi
done <"$BASELINE"

# Per frame: the sum of its stages (pipeline: detection, pad fix and estimator; target; encode).
echo
printf '%-28s %12s %8s\n' "frame (all stages)" insns insn/px
awk -F'[: ]' '{ sum[$1] += $NF; if (!($1 in seen)) { seen[$1] = 1; order[n++] = $1 } }
    END { for (i = 0; i < n; i++) print order[i], sum[order[i]] }' "$counts" |
    while read -r frame total; do
        px=$(pixels_of "$frame")
        printf '%-28s %12d %8s\n' "$frame" "$total" \
            "$(awk -v n="$total" -v p="$px" 'BEGIN { if (p > 0) printf "%.1f", n / p; else print "-" }')"
    done

echo
if [ "${improved:-0}" -eq 1 ]; then
    echo "m7_check: some regions got more than ${TOLERANCE}% cheaper: run scripts/m7_check.sh --update and commit ${BASELINE}"
fi
if [ "$status" -ne 0 ]; then
    echo "m7_check: FAILED: regions grew by more than ${TOLERANCE}% or do not match the baseline (see above)" >&2
    echo "  intended? run scripts/m7_check.sh --update and commit ${BASELINE}" >&2
    exit 1
fi
echo "m7_check: ok ($(wc -l <"$counts") regions within ${TOLERANCE}% of ${BASELINE})"
