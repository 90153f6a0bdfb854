#!/usr/bin/env python3
"""Where a frame's Cortex-M7 instructions go: the benchmark of scripts/m7_check.sh, per function.

Usage
-----
    python3 scripts/m7_profile.py                          # every region, top 12 functions
    python3 scripts/m7_profile.py qvga-adv-noise --top 20  # regions whose label contains this
    python3 scripts/m7_profile.py qvga-adv-noise --annotate Tracer::trace
    python3 scripts/m7_profile.py vga-adv-noise --against vga-flat

`scripts/m7_check.sh` says how many instructions each region of the benchmark (bench/m7) costs;
this says which functions they are spent in, exactly (the same QEMU machine, counted per
instruction address by the TCG plugin bench/m7/profile/m7prof.c). Inlined code counts for the
function it was inlined into.

- `LABEL...`: only regions whose label ("qvga-adv-noise: pipeline") contains one of these.
- `--top N`: functions listed per region (default 12).
- `--annotate NAME`: the disassembly of the function(s) whose demangled name contains NAME,
  each instruction with its count, for each selected region (instructions never executed in
  any selected region left out).
- `--against LABEL`: a second count column from the region of that label (the same
  function's cost on, say, a flat frame), to see what the content adds.

Needs what m7_check.sh needs (QEMU with m7count's setup, the thumbv7em target) plus gcc and
arm-none-eabi-objdump / nm (binutils-arm-none-eabi). The plugin is built with m7count's copy
of QEMU's plugin header (`$M7COUNT`'s directory, plugin/qemu-plugin.h, written by its
setup.sh) into bench/m7/target/m7prof/.
"""

import argparse
import bisect
import os
import re
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(REPO, "bench", "m7")
ELF = os.path.join(BENCH, "target", "thumbv7em-none-eabihf", "release", "touchdown-m7bench")
LABEL = re.compile(r"^([a-z0-9][a-z0-9-]*: [a-z0-9][a-z0-9-]*)$")


def m7count_dir():
    script = os.environ.get("M7COUNT") or os.path.join(os.path.dirname(REPO), "shared", "tools", "m7count",
                                                      "m7count.sh")
    return os.path.dirname(os.path.abspath(script))


def build_plugin():
    header_dir = os.path.join(m7count_dir(), "plugin")
    if not os.path.isfile(os.path.join(header_dir, "qemu-plugin.h")):
        sys.exit("error: no qemu-plugin.h in %s: run m7count's setup.sh once (as root), or set M7COUNT "
                 "to its m7count.sh" % header_dir)
    out_dir = os.path.join(BENCH, "target", "m7prof")
    os.makedirs(out_dir, exist_ok=True)
    plugin = os.path.join(out_dir, "libm7prof.so")
    source = os.path.join(BENCH, "profile", "m7prof.c")
    if not os.path.isfile(plugin) or os.path.getmtime(plugin) < os.path.getmtime(source):
        subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-I", header_dir, "-o", plugin, source], check=True)
    return plugin


def symbols(tool):
    """Sorted (start, size, demangled name) of the ELF's functions."""
    listing = subprocess.run([tool, "-S", "-C", ELF], check=True, capture_output=True, text=True).stdout
    found = []
    for line in listing.splitlines():
        parts = line.split(None, 3)
        if len(parts) == 4 and parts[2] in "tTwW":
            name = re.sub(r"::h[0-9a-f]{16}$", "", parts[3])
            found.append((int(parts[0], 16) & ~1, int(parts[1], 16), name))
    found.sort()
    return found


def marker(tool, name):
    listing = subprocess.run([tool, ELF], check=True, capture_output=True, text=True).stdout
    for line in listing.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[2] == name:
            return "0x" + parts[0]
    sys.exit("error: %s has no symbol %s" % (ELF, name))


def run(plugin, tool, out_dir):
    """Runs the benchmark under the plugin; returns the region labels in order."""
    command = ["qemu-system-arm", "-machine", "mps2-an500", "-cpu", "cortex-m7", "-nographic",
               "-monitor", "none", "-serial", "null", "-semihosting-config", "enable=on,target=native",
               "-plugin", "%s,start=%s,stop=%s,dir=%s" % (plugin, marker(tool, "m7bench_start"),
                                                        marker(tool, "m7bench_stop"), out_dir),
               "-d", "plugin", "-kernel", ELF]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    labels = [m.group(1) for m in (LABEL.match(line) for line in (done.stdout + done.stderr).splitlines()) if m]
    if done.returncode != 0:
        sys.stderr.write(done.stdout + done.stderr)
        sys.exit("error: the benchmark exited with status %d" % done.returncode)
    return labels


def read_counts(path):
    counts = {}
    with open(path) as f:
        for line in f:
            address, count = line.split()
            counts[int(address, 16)] = int(count)
    return counts


def per_function(counts, syms):
    starts = [s[0] for s in syms]
    totals = {}
    for address, count in counts.items():
        i = bisect.bisect_right(starts, address) - 1
        name = syms[i][2] if i >= 0 and address < syms[i][0] + syms[i][1] else "(no symbol)"
        totals[name] = totals.get(name, 0) + count
    return totals


def annotate(name_part, syms, columns, objdump):
    for start, size, name in syms:
        if name_part not in name or size == 0:
            continue
        listing = subprocess.run([objdump, "-d", "--no-show-raw-insn", "--start-address=%#x" % start,
                                  "--stop-address=%#x" % (start + size), ELF],
                                 check=True, capture_output=True, text=True).stdout
        print("\n-- %s (%s)" % (name, ", ".join(title for title, _ in columns)))
        for line in listing.splitlines():
            head = line.strip().split(":", 1)[0]
            try:
                address = int(head, 16)
            except ValueError:
                continue
            row = [counts.get(address, 0) for _, counts in columns]
            if any(row):
                print(" ".join("%10d" % c for c in row), line.rstrip())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("labels", nargs="*", help="only regions whose label contains one of these")
    parser.add_argument("--top", type=int, default=12, help="functions per region (default 12)")
    parser.add_argument("--annotate", metavar="NAME", help="per-instruction counts of functions matching NAME")
    parser.add_argument("--against", metavar="LABEL", help="a second column from the region with this label")
    args = parser.parse_args()

    nm = "arm-none-eabi-nm"
    objdump = "arm-none-eabi-objdump"
    for tool in (nm, objdump, "gcc", "qemu-system-arm"):
        if subprocess.run(["which", tool], capture_output=True).returncode != 0:
            sys.exit("error: %s not found (m7count's setup.sh installs QEMU and binutils-arm-none-eabi)" % tool)
    print("m7_profile: building bench/m7 (cargo build --release)", file=sys.stderr, flush=True)
    subprocess.run(["cargo", "build", "--release", "-q"], cwd=BENCH, check=True)
    plugin = build_plugin()
    syms = symbols(nm)
    with tempfile.TemporaryDirectory() as out_dir:
        labels = run(plugin, nm, out_dir)
        regions = [(label, read_counts(os.path.join(out_dir, "region-%d.txt" % k)))
                   for k, label in enumerate(labels) if os.path.isfile(os.path.join(out_dir, "region-%d.txt" % k))]
    if args.against and not any(args.against in label for label, _ in regions):
        sys.exit("error: no region's label contains %r" % args.against)
    selected = [(label, counts) for label, counts in regions
                if not args.labels or any(part in label for part in args.labels)]
    if not selected:
        sys.exit("error: no region's label contains any of %s (labels: %s)" % (args.labels, ", ".join(labels)))
    for label, counts in selected:
        against = None
        if args.against:
            # The same stage of the other frame ("vga-flat: pipeline" for "vga-adv-noise:
            # pipeline"), else its first region.
            stage = label.split(": ", 1)[-1]
            matches = [c for other, c in regions if args.against in other]
            staged = [c for other, c in regions if args.against in other and other.endswith(": " + stage)]
            against = (staged or matches)[0]
        totals = per_function(counts, syms)
        total = sum(totals.values())
        other = per_function(against, syms) if against is not None else None
        print("\n== %s: %d instructions" % (label, total))
        for name, count in sorted(totals.items(), key=lambda item: -item[1])[:args.top]:
            extra = "" if other is None else " %10d" % other.get(name, 0)
            print("%10d %5.1f%%%s  %s" % (count, 100.0 * count / max(total, 1), extra, name[:140]))
        if args.annotate:
            columns = [(label, counts)] + ([(args.against, against)] if against is not None else [])
            annotate(args.annotate, syms, columns, objdump)


if __name__ == "__main__":
    main()
