#!/usr/bin/env bash
# Emulated boot test and firmware-in-the-loop (firmware/emu/README.md): builds the release
# firmware for every board, frame size and clock variant, and runs each ELF, unchanged, on the
# emulated STM32H743 from its reset vector until every task waits at its first await, then
# for EMU_FIL_SECONDS (default 2) of emulated time against the emulated camera and autopilot,
# checking the LANDING_TARGETs it sends to an emulated ArduPilot (and, for the VGA build, to
# an emulated PX4); on one variant per board FIL ends with a parameter set over MAVLink, a
# power cycle and the parameter read back; on the default build it first streams frames to
# `touchdown view --record` over RTT. The default build also runs the short soak
# (firmware/emu/soak.py: line noise, an autopilot reboot, parameter floods signed and
# unsigned, dropped frames and a brown-out during a save, each followed by checks; the
# 10-minute one is measured in firmware/emu/README.md). Before them, the emulator's
# own unit tests; after them, six self-tests that must fail: a PLL that never locks (the
# boot), a camera that never answers (the watchdog must reset the board), a sensor deaf to
# its exposure registers (the frames stay clipped), a power cycle that loses the flash
# (the parameter is gone), a viewer whose requests never reach the board (the board, which
# streams only when asked, sends nothing) and, in the soak, a pad that never comes back into
# view (the targets do not resume).
#
# Usage: scripts/emu_boot.sh [VARIANT...]   (default: all; names below)
# EMU_SKIP_BUILD=1 reuses the ELFs already in $CARGO_TARGET_DIR/emu/; EMU_FIL_SECONDS=0 runs
# the boot test only; EMU_SOAK_SECONDS (default 15) is the short soak's emulated time (its
# first round of disturbances always runs whole), 0 skips it.
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

readonly FIL_SECONDS="${EMU_FIL_SECONDS:-2}"
readonly SOAK_SECONDS="${EMU_SOAK_SECONDS:-15}"

# What a variant's FIL does beyond landing against an emulated ArduPilot on a clean line:
# - `--power-cycle`: ends with the parameter power cycle (firmware/emu/power_cycle.py), on
#   one variant per board (the OpenMV Cam's starts with foreign data in a parameter sector);
# - `--line-noise`: the autopilot line carries garbage before a quarter of its messages
#   (autopilot.py): the firmware must resynchronise and land as on a clean line;
# - `--autopilot ardupilot-4.7`: an ArduPilot 4.7 that sets TD_PROFILE 3, LANDING_TARGETs in
#   LOCAL_FRD, levelled with the attitude;
# - `--signing`: a signing key set over MAVLink, signed, unsigned and replayed PARAM_SETs, a
#   power cycle, the key and the checks again (firmware/emu/signing.py);
# - `--lens TOUCHDOWN`: a longer lens and the pad's design set by `touchdown board` over the
#   UART, a power cycle and both read back (firmware/emu/lens.py);
# - `--view TOUCHDOWN`: the frame stream over RTT channel 1 served on a TCP port, recorded
#   by `touchdown view --record` and replayed by `touchdown detect` (firmware/emu/view.py);
#   TOUCHDOWN (here and for --lens) is the test step's debug build (built here when missing).
# The other variants differ only in the camera and the clock.
readonly VIEWER="${TOUCHDOWN:-${TARGET_DIR}/debug/touchdown}"
declare -rA FIL_EXTRAS=(
    [nucleo-qvga]="--power-cycle --view ${VIEWER}"
    [openmv-qvga]="--power-cycle"
    [nucleo-qvga-480]="--line-noise --lens ${VIEWER}"
    [openmv-vga]="--autopilot ardupilot-4.7"
    [nucleo-vga]="--signing"
)
# name board MHz camera cargo-features...
readonly VARIANTS=(
    "nucleo-qvga nucleo 400 qvga"
    "nucleo-vga nucleo 400 vga --features camera-vga"
    "nucleo-qvga-480 nucleo 480 qvga --features clk-480mhz"
    "openmv-qvga openmv 400 qvga --no-default-features --features board-openmv"
    "openmv-vga openmv 400 vga --no-default-features --features board-openmv,camera-vga"
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
    shift 4
    local t0
    t0=$(date +%s)
    cargo build --quiet --release -p touchdown-firmware --target "${TARGET}" "$@" || return
    cp "${TARGET_DIR}/${TARGET}/release/touchdown-firmware" "${OUT}/${name}"
    echo "built ${name} in $(($(date +%s) - t0)) s"
}

emulate() {
    PYTHONPATH=firmware python3 -m emu "$@"
}

# expect_failure LABEL ARGS...: the run must fail (the emulator catches the broken chip).
expect_failure() {
    local label=$1
    shift
    echo
    echo "self-test: ${label}: the run must FAIL"
    if emulate "$@" --label "${label}"; then
        echo "self-test FAILED: the emulator passed a firmware/chip that cannot work"
        return 1
    fi
    echo "self-test ok: caught"
}

mkdir -p "${OUT}"
failed=0
if [ "${FIL_SECONDS}" != 0 ] && [ ! -x "${VIEWER}" ]; then
    cargo build --quiet -p touchdown-cli --bin touchdown || exit 1
fi
echo "emulator unit tests (firmware/emu/test_*.py)"
python3 -m unittest discover --quiet -s firmware/emu -t firmware || failed=1
for variant in "${VARIANTS[@]}"; do
    read -r -a v <<<"${variant}"
    selected "${v[0]}" "$@" || continue
    if [ "${EMU_SKIP_BUILD:-0}" != 1 ]; then
        build "${v[@]}" || { echo "build of ${v[0]} FAILED"; failed=1; continue; }
    fi
    fil=()
    if [ "${FIL_SECONDS}" != 0 ]; then
        read -r -a extras <<<"${FIL_EXTRAS[${v[0]}]:-}"
        fil=(--fil "${FIL_SECONDS}" --camera "${v[3]}" "${extras[@]}")
    fi
    emulate "${OUT}/${v[0]}" --board "${v[1]}" --cpu-mhz "${v[2]}" --label "${v[0]}" \
        "${fil[@]}" || failed=1
done

readonly DEFAULT_ELF="${OUT}/nucleo-qvga"
readonly VGA_ELF="${OUT}/nucleo-vga"
if [ -f "${VGA_ELF}" ] && [ "${FIL_SECONDS}" != 0 ] && selected nucleo-vga "$@"; then
    # Against PX4, whose profile needs the vehicle's attitude and position and whose TIMESYNC
    # requests must be answered within 10 ms: the VGA build, whose frames take longest, on a
    # noisy line.
    emulate "${VGA_ELF}" --board nucleo --fil "${FIL_SECONDS}" --camera vga --autopilot px4 \
        --line-noise --label "nucleo-vga, PX4, line noise" || failed=1
fi
if [ -f "${DEFAULT_ELF}" ] && [ "${FIL_SECONDS}" != 0 ] && [ "${SOAK_SECONDS}" != 0 ] &&
    selected nucleo-qvga "$@"; then
    # The short soak: one of each disturbance (the signed flood sets a signing key), then more
    # while the time lasts; about a minute of wall time.
    emulate "${DEFAULT_ELF}" --board nucleo --fil "${SOAK_SECONDS}" --camera qvga --soak \
        --soak-signing --label "nucleo-qvga, soak" || failed=1
fi
if [ -f "${DEFAULT_ELF}" ]; then
    expect_failure "nucleo-qvga, PLL1RDY stuck at 0" "${DEFAULT_ELF}" --board nucleo \
        --inject no-pll1rdy --spin-bound 20000 || failed=1
    expect_failure "nucleo-qvga, no camera on the SCCB bus" "${DEFAULT_ELF}" --board nucleo \
        --inject no-camera --fil 4 || failed=1
    expect_failure "nucleo-qvga, a sensor that ignores its exposure registers" "${DEFAULT_ELF}" \
        --board nucleo --inject fixed-exposure --fil 1 || failed=1
    expect_failure "nucleo-qvga, a power cycle that loses the flash" "${DEFAULT_ELF}" \
        --board nucleo --inject volatile-flash --fil 1 --power-cycle || failed=1
    if [ "${FIL_SECONDS}" != 0 ]; then
        expect_failure "nucleo-qvga, a viewer whose requests never reach the board" \
            "${DEFAULT_ELF}" --board nucleo --inject view-unasked --fil 1 --view "${VIEWER}" ||
            failed=1
    fi
    if [ "${SOAK_SECONDS}" != 0 ]; then
        expect_failure "nucleo-qvga, soak: the pad never comes back after the first disturbance" \
            "${DEFAULT_ELF}" --board nucleo --inject pad-lost --fil 4 --camera qvga --soak \
            --soak-seed 4 || failed=1
    fi
fi
exit "${failed}"
