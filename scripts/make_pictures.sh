#!/usr/bin/env bash
# Regenerates the documentation's pictures in docs/pictures/ with touchdown's own commands.
#
#   scripts/make_pictures.sh            every picture (the landing replay takes a few minutes)
#   THREADS=1 scripts/make_pictures.sh  render on one thread (a shared machine)
#
# Each picture's caption (README.md, docs/) names the command that made it; this script runs
# exactly those, in a scratch directory, and copies only the files the docs show. The
# simulated pictures are deterministic (seed 1), so an unchanged tree gives the same images.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
out="$root/docs/pictures"
threads=${THREADS:-0}
mkdir -p "$out"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT

cargo build --release -p touchdown-cli --manifest-path "$root/Cargo.toml" ${CARGO_JOBS:+-j "$CARGO_JOBS"}
touchdown="$root/target/release/touchdown"
thread_args=()
if [ "$threads" != 0 ]; then
    thread_args=(--threads "$threads")
fi

cd "$scratch"

# The pad: the recommended nested-field design at true size (pad.svg is in millimetres).
"$touchdown" pad --design nested-field --out pad >/dev/null
cp pad/pad.svg "$out/pad-nested-field.svg"

# What the camera sees: the first frame of the set-up guide's calibration hover (3 m over the
# nested pad, 640x480), with the markers touchdown finds outlined, shown at half size (a
# full-size noisy frame is a 400 KB PNG).
"$touchdown" simulate --scenario hover --frames 1 --out hover "${thread_args[@]}" >/dev/null
"$touchdown" detect --camera hover/camera.toml --pad hover/pad.toml \
    --draw "$out/detect-hover.png" --draw-scale 2 hover/frames/000000.pgm

# A landing: 40 m to 0.5 m over the nested pad against the simulated ArduPilot, the mount
# calibrated in the set-up guide's hover first; the altitude and the horizontal error plots.
"$touchdown" replay --scenario landing --calibration-hover --plots landing "${thread_args[@]}" \
    >landing.txt
cp landing/position-z.png "$out/landing-position-z.png"
cp landing/error-x.png "$out/landing-error-x.png"

# The drawn diagrams.
python3 "$root/scripts/diagrams.py" wiring "$out/wiring.svg"
python3 "$root/scripts/diagrams.py" pipeline "$out/pipeline.svg"

ls -l "$out"
