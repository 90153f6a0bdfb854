#!/usr/bin/env bash
# Emulated boot test (firmware/emu/README.md): builds the release firmware for every board,
# frame size and clock variant, and runs each ELF, unchanged, on the emulated STM32H743 from
# its reset vector until every task waits at its first await. Then a self-test: the same run
# with a PLL that never locks must fail, so a passing result means something.
#
# Usage: scripts/emu_boot.sh [VARIANT...]   (default: all; names below)
# EMU_SKIP_BUILD=1 reuses the ELFs already in $CARGO_TARGET_DIR/emu/.
#
# The builds share one target directory, one after the other: the NUCLEO variants first (the
# default build is usually there already), then the OpenMV ones (another chip feature, so
# embassy-stm32 is rebuilt once). Each ELF is copied to target/emu/<variant> before the next
# build overwrites it.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

readonly TARGET=thumbv7em-none-eabihf
readonly TARGET_DIR="${CARGO_TARGET_DIR:-target}"
readonly OUT="${TARGET_DIR}/emu"

# name board MHz cargo-features...
readonly VARIANTS=(
    "nucleo-qvga nucleo 400"
    "nucleo-vga nucleo 400 --features camera-vga"
    "nucleo-qvga-480 nucleo 480 --features clk-480mhz"
    "openmv-qvga openmv 400 --no-default-features --features board-openmv"
    "openmv-vga openmv 400 --no-default-features --features board-openmv,camera-vga"
)

selected() {
    local name=$1
    shift
    [ "$#" -eq 0 ] && return 0
    local want
    for want in "$@"; do
        [ "$want" = "$name" ] && return 0
    done
    return 1
}

build() {
    local name=$1
    shift 3
    local t0
    t0=$(date +%s)
    cargo build --quiet --release -p touchdown-firmware --target "${TARGET}" "$@" || return
    cp "${TARGET_DIR}/${TARGET}/release/touchdown-firmware" "${OUT}/${name}"
    echo "built ${name} in $(($(date +%s) - t0)) s"
}

emulate() {
    PYTHONPATH=firmware python3 -m emu "$@"
}

mkdir -p "${OUT}"
failed=0
for variant in "${VARIANTS[@]}"; do
    read -r -a v <<<"${variant}"
    selected "${v[0]}" "$@" || continue
    if [ "${EMU_SKIP_BUILD:-0}" != 1 ]; then
        build "${v[@]}" || { echo "build of ${v[0]} FAILED"; failed=1; continue; }
    fi
    emulate "${OUT}/${v[0]}" --board "${v[1]}" --cpu-mhz "${v[2]}" --label "${v[0]}" || failed=1
done

first=$(find "${OUT}" -maxdepth 1 -name 'nucleo-qvga' -print -quit)
if [ -n "${first}" ]; then
    echo
    echo "self-test: PLL1 never locks, the boot test must FAIL"
    if emulate "${first}" --board nucleo --label "nucleo-qvga, PLL1RDY stuck at 0" \
        --inject no-pll1rdy --spin-bound 20000; then
        echo "self-test FAILED: the emulator passed a firmware that cannot boot"
        failed=1
    else
        echo "self-test ok: the stuck PLL was caught"
    fi
fi
exit "${failed}"
