#!/usr/bin/env bash
# nopanic_check.sh: proves at link time that touchdown-core's per-frame path cannot panic.
#
# usage: scripts/nopanic_check.sh [--find]
#   --find   instead of the check, build with a real panic handler and list every call into
#            core::panicking with its source location (the inlined call chain), to fix them
#
# Builds nopanic/ (excluded from the workspace) for thumbv7em-none-eabihf with the firmware's
# release profile. Its entry point runs detection, pose, pad fix, the trackers and the
# companion's MAVLink parse/encode on inputs the optimiser cannot see, and its panic handler
# calls a function that is defined nowhere: the link succeeds only if no panic is reachable.
# Then a canary build (the same image plus one deliberate out-of-bounds index) must FAIL to
# link, so a green result cannot come from the check having stopped checking.
#
# Exit 0: no reachable panic. Exit 1: a panic is reachable (or the canary linked); the output
# says which and how to find the site. Needs the thumbv7em-none-eabihf target (rustup target
# add thumbv7em-none-eabihf); --find also needs arm-none-eabi-objdump/addr2line (apt-get
# install binutils-arm-none-eabi).
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
readonly TARGET=thumbv7em-none-eabihf
readonly MANIFEST=nopanic/Cargo.toml
readonly TARGET_DIR="${CARGO_TARGET_DIR:-target}/nopanic"
readonly ELF="$TARGET_DIR/$TARGET/release/touchdown-nopanic"
readonly MISSING=touchdown_core_per_frame_path_can_panic
# RUSTFLAGS replaces the repository's [target.thumbv7em-none-eabihf] rustflags, which link
# with cortex-m-rt's and defmt's linker scripts that this bare image does not use.
export RUSTFLAGS="-C target-cpu=cortex-m7"

build() {
    cargo build --release --manifest-path "$MANIFEST" --target "$TARGET" \
        --target-dir "$TARGET_DIR" "$@" 2>&1
}

if [ "${1:-}" = "--find" ]; then
    build --features find-panics | tail -n 3
    objdump=arm-none-eabi-objdump
    addr2line=arm-none-eabi-addr2line
    # Every direct call to a core panic entry point, with its inlined call chain.
    panics=$(arm-none-eabi-nm "$ELF" | awk '/panicking|unwrap_failed|expect_failed|slice_index_fail|index_out_of_bounds|ord_violation|panic_bounds_check/ {print $1}' | sed 's/^0*//')
    if [ -z "$panics" ]; then
        echo "no core::panicking symbols in the image: nothing to find"
        exit 0
    fi
    pattern=$(echo "$panics" | paste -sd'|')
    "$objdump" -d --no-show-raw-insn "$ELF" | grep -E "\s(bl|b|b\.w)\s+($pattern)\s" | while read -r addr _ _ target; do
        echo "== call at 0x${addr%:} to $target"
        "$addr2line" -i -f -C -e "$ELF" "0x${addr%:}" | paste - - | awk '{print "   ", $1, $NF}'
    done
    exit 0
fi

t0=$(date +%s)
echo "nopanic: building the per-frame path for $TARGET (firmware release profile)..."
if ! out=$(build); then
    if grep -q "$MISSING" <<<"$out"; then
        echo "$out" | grep -E "undefined symbol|referenced by" | head -n 6
        echo "nopanic: FAILED: a panic is reachable from the per-frame path of touchdown-core."
        echo "  Run scripts/nopanic_check.sh --find to list the panicking call sites, then replace"
        echo "  the indexing/unwrap/slicing there with checked forms (get, checked_*, min/max)."
    else
        echo "$out" | tail -n 30
        echo "nopanic: FAILED: the image did not build (see the errors above)."
    fi
    exit 1
fi
echo "nopanic: linked: no panic is reachable from detect, pose, pad fix, filter, MAVLink parse/encode, the exposure loop and settings, the frame timing and the frame stream."

# The canary: the same image with one deliberate out-of-bounds index must not link.
if out=$(build --features canary); then
    echo "nopanic: FAILED: the canary (a deliberate out-of-bounds index) linked, so the check proves nothing."
    exit 1
fi
if ! grep -q "$MISSING" <<<"$out"; then
    echo "$out" | tail -n 30
    echo "nopanic: FAILED: the canary build failed for another reason (see above)."
    exit 1
fi
echo "nopanic: canary with a deliberate panic failed to link, as it must."
echo "nopanic: ok in $(($(date +%s) - t0)) s"
