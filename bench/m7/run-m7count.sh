#!/usr/bin/env bash
# Cargo runner of the M7 benchmark: runs the ELF under m7count.sh (QEMU mps2-an500 + the
# instruction-counting TCG plugin). Extra m7count options come from M7COUNT_ARGS, e.g.
#   M7COUNT_ARGS="-H 20" cargo run --release
# m7count.sh is looked up in $M7COUNT (the script itself), then next to this repository
# (../../../shared/tools/m7count/m7count.sh from bench/m7).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
m7count="${M7COUNT:-$here/../../../shared/tools/m7count/m7count.sh}"
if [ ! -x "$m7count" ] && [ ! -f "$m7count" ]; then
    echo "run-m7count.sh: m7count.sh not found at $m7count" >&2
    echo "  set M7COUNT=/path/to/m7count.sh, or place the shared tools next to the repository" >&2
    echo "  (shared/tools/m7count; run its setup.sh once as root to install QEMU and the plugin)." >&2
    exit 2
fi
# shellcheck disable=SC2086 # M7COUNT_ARGS is a list of options
exec bash "$m7count" ${M7COUNT_ARGS:-} "$@"
