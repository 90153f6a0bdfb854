#!/usr/bin/env bash
# A precision-landing rehearsal against a real autopilot SITL, in one command: starts ArduCopter
# or PX4 (SIH) in a fresh directory, flies `touchdown sitl --gcs` against it (parameters, take-off,
# a move off the pad, the landing, until the autopilot disarms) and checks the SITL's own truth.
#
# usage: scripts/sitl_rehearsal.sh [--limit-cm N] [--keep DIR] arducopter|px4 [touchdown sitl options...]
#
#   --limit-cm N   fail when touchdown is more than N cm from the pad centre (default 10)
#   --keep DIR     run the SITL in DIR (kept: its logs, parameters, our JSON) instead of a
#                  temporary directory
#   options after the autopilot go to `touchdown sitl` as they are (e.g. --height 15 --offset 2
#   --wind-mps 3 --turbulence 1 --qvga --fps 10 --seed 2; ArduCopter without GPS after the
#   climb: --height 12 --gps-loss-height 12)
#
# Environment:
#   SITL_DIR        the SITL builds (arducopter/arducopter, px4/bin/px4, px4/etc); default the
#                   shared tools beside the repository, ../shared/tools/sitl. Absent: the script
#                   prints that it skips and exits 0.
#   SITL_INSTANCE   instance number N (default 0): ArduCopter -I N (ports + 10 N), PX4 -i N
#                   (ports + N), so that rehearsals can run beside other SITLs.
#   TOUCHDOWN       the touchdown binary (default target/release/touchdown, built if missing).
#
# Exit status: 0 landed within the limit, disarmed, no re-take-off (or skipped: no SITL);
# 1 the rehearsal failed (the reason on the last line); 2 a bad option.
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
sitl_dir=${SITL_DIR:-${repo}/../shared/tools/sitl}
instance=${SITL_INSTANCE:-0}
limit_cm=10
keep=""

while [ $# -gt 0 ]; do
    case "$1" in
        --limit-cm) limit_cm=${2:?--limit-cm needs a number}; shift 2 ;;
        --keep) keep=${2:?--keep needs a directory}; shift 2 ;;
        -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
        *) break ;;
    esac
done
autopilot=${1:-}
if [ "$autopilot" != arducopter ] && [ "$autopilot" != px4 ]; then
    echo "usage: scripts/sitl_rehearsal.sh [--limit-cm N] [--keep DIR] arducopter|px4 [touchdown sitl options...]" >&2
    exit 2
fi
shift
if ! [[ "$limit_cm" =~ ^[0-9]+([.][0-9]+)?$ ]] || ! [[ "$instance" =~ ^[0-9]+$ ]]; then
    echo "error: --limit-cm and SITL_INSTANCE take numbers" >&2
    exit 2
fi

case "$autopilot" in
    arducopter) sitl_name=arducopter/arducopter ;;
    px4) sitl_name=px4/bin/px4 ;;
esac
if [ ! -x "${sitl_dir}/${sitl_name}" ]; then
    echo "skipping the ${autopilot} rehearsal: no SITL at ${sitl_dir}/${sitl_name} (set SITL_DIR)"
    exit 0
fi
# Absolute: the SITL runs in its own directory.
sitl_dir=$(cd "$sitl_dir" && pwd)
sitl_bin=${sitl_dir}/${sitl_name}

touchdown=${TOUCHDOWN:-${repo}/target/release/touchdown}
case "$touchdown" in
    /*) ;;
    *) touchdown=${PWD}/${touchdown} ;;
esac
if [ ! -x "$touchdown" ]; then
    echo "building touchdown (release)"
    (cd "$repo" && cargo build --release --quiet -p touchdown-cli)
fi

if [ -n "$keep" ]; then
    mkdir -p "$keep"
    run_dir=$(cd "$keep" && pwd)
    if [ -n "$(ls -A "$run_dir")" ]; then
        echo "error: --keep ${keep}: the directory is not empty (the SITL keeps its state there)" >&2
        exit 2
    fi
else
    run_dir=$(mktemp -d "${TMPDIR:-/tmp}/touchdown-rehearsal.XXXXXX")
fi

sitl_pid=""
cleanup() {
    if [ -n "$sitl_pid" ] && kill -0 "$sitl_pid" 2>/dev/null; then
        kill "$sitl_pid" 2>/dev/null || true
        wait "$sitl_pid" 2>/dev/null || true
    fi
    if [ -z "$keep" ]; then
        rm -rf "$run_dir"
    fi
}
trap cleanup EXIT

case "$autopilot" in
    arducopter)
        gcs_port=$((5760 + 10 * instance))
        board_port=$((5762 + 10 * instance))
        (cd "$run_dir" && exec "$sitl_bin" --model quad --defaults "${sitl_dir}/arducopter/copter.parm" \
            -I "$instance" >sitl.log 2>&1) &
        sitl_pid=$!
        links=(--tcp "127.0.0.1:${board_port}" --gcs "tcp:127.0.0.1:${gcs_port}")
        ;;
    px4)
        # PX4's start-up scripts call its commands as `px4-NAME`, links to the px4 binary. A copy
        # of the build that lost those links (plain files holding "px4") gets a directory of
        # links of its own, first in PATH.
        bin_dir="${sitl_dir}/px4/bin"
        if [ ! -x "${bin_dir}/px4-param" ]; then
            bin_dir="${run_dir}/bin"
            mkdir -p "$bin_dir"
            for f in "${sitl_dir}"/px4/bin/px4-*; do
                if [ "$(head -c 16 "$f")" = px4 ]; then
                    ln -s "${sitl_dir}/px4/bin/px4" "${bin_dir}/$(basename "$f")"
                else
                    cp "$f" "$bin_dir/"
                fi
            done
            ln -s "${sitl_dir}/px4/bin/px4" "${bin_dir}/px4"
        fi
        (cd "$run_dir" && PATH="${bin_dir}:${PATH}" PX4_SYS_AUTOSTART=10040 \
            PX4_SIM_MODEL=sihsim_quadx PX4_SIMULATOR=sihsim \
            exec "${bin_dir}/px4" -i "$instance" -d "${sitl_dir}/px4/etc" >sitl.log 2>&1 </dev/null) &
        sitl_pid=$!
        links=(--udp "127.0.0.1:$((14580 + instance))" --udp-local-port "$((14540 + instance))"
            --gcs "udp:127.0.0.1:$((18570 + instance))")
        # PX4 instance N is MAVLink system N + 1: the board takes its profile only from the
        # HEARTBEAT of system TD_SYSID.
        if [ "$instance" -ne 0 ]; then
            sysid="TD_SYSID=$((instance + 1))"
            args=()
            merged=""
            while [ $# -gt 0 ]; do
                if [ "$1" = --board-params ] && [ $# -gt 1 ]; then
                    args+=("$1" "$2,${sysid}")
                    merged=1
                    shift 2
                else
                    args+=("$1")
                    shift
                fi
            done
            [ -n "$merged" ] || args+=(--board-params "$sysid")
            set -- "${args[@]}"
        fi
        ;;
esac

echo "rehearsal (${autopilot}): SITL in ${run_dir}; touchdown sitl ${links[*]} $*"
status=0
"$touchdown" sitl "${links[@]}" "$@" --json >"${run_dir}/landing.json" 2>"${run_dir}/touchdown.log" || status=$?
cat "${run_dir}/touchdown.log"
if ! kill -0 "$sitl_pid" 2>/dev/null; then
    echo "the SITL exited during the rehearsal; its last lines:"
    tail -n 20 "${run_dir}/sitl.log"
fi
# The verdict from the JSON line (touchdown's exit status already covers no touchdown, no
# disarm and a re-take-off; the distance limit is the rehearsal's own).
python3 - "${run_dir}/landing.json" "$limit_cm" "$autopilot" "$status" <<'EOF'
import json, sys
path, limit, autopilot, status = sys.argv[1], float(sys.argv[2]), sys.argv[3], int(sys.argv[4])
try:
    with open(path) as f:
        r = json.load(f)
except (OSError, ValueError):
    print(f"rehearsal {autopilot}: FAILED: no result from touchdown sitl (exit {status})")
    sys.exit(1)
h = r.get("horizontal_cm")
lag = r.get("lag_ms_mean")
reh = r.get("rehearsal") or {}
line = (f"rehearsal {autopilot}: touchdown "
        + ("-" if h is None else f"{h:.1f} cm") + f" from the pad (limit {limit:g})"
        + f", {r.get('targets_sent', 0)} targets, lag "
        + ("-" if lag is None else f"{lag:.0f} ms") + f", {r.get('frames_skipped', 0)} frames skipped"
        + f", landing started {reh.get('landing_height_m') or 0:.1f} m up")
loss = reh.get("gps_loss")
if loss is not None:
    lost_m = loss.get("source_switched_height_m")
    line += (", GPS not lost" if loss.get("gps_off_s") is None or lost_m is None
             else f", GPS lost at {lost_m:.1f} m")
if status != 0 or h is None:
    print(f"{line}: FAILED (touchdown sitl exit {status})")
    sys.exit(1)
if h > limit:
    print(f"{line}: FAILED (over the limit)")
    sys.exit(1)
print(f"{line}: ok")
EOF
