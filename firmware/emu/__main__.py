"""Runs one touchdown firmware ELF on the emulated STM32H743 and prints a summary.

    python3 -m emu ELF --board nucleo|openmv [--cpu-mhz 400|480] [--fil SECONDS [--power-cycle]
        [--view TOUCHDOWN] [--lens TOUCHDOWN] | --fil SECONDS --soak [--soak-seed N] [--soak-signing]]

Without --fil: the boot test (boot.py). With --fil: the boot test, then firmware-in-the-loop
(fil.py) for SECONDS of emulated time; with --power-cycle also a parameter set over MAVLink,
kept through a power cycle (power_cycle.py); with --view, the frame stream recorded by
`touchdown view` and replayed (view.py); with --lens, a lens and a pad design set by
`touchdown board` and kept through a power cycle (lens.py); with --soak, FIL under a seeded schedule of
disturbances for SECONDS instead (soak.py). Exit status 0 when every check passed, 1 on a failure
(the message names the pc, the function and the address), 2 on bad usage.
"""

import argparse
import sys
import time

from .board import BOARDS
from .boot import report_stack, run_boot
from .chip import build_chip
from .elfimage import ElfImage


def parse(argv):
    parser = argparse.ArgumentParser(prog="emu", description=__doc__.split("\n")[0])
    parser.add_argument("elf")
    parser.add_argument("--board", choices=sorted(BOARDS), required=True)
    parser.add_argument("--cpu-mhz", type=int, choices=(400, 480), default=400)
    parser.add_argument("--label", help="name of this build in the summary")
    parser.add_argument("--spin-bound", type=int, default=100_000,
                        help="reads of one register from one pc without a change that count "
                             "as a hang")
    parser.add_argument("--inject",
                        choices=("no-pll1rdy", "no-camera", "fixed-exposure", "volatile-flash",
                                 "pad-lost", "view-unasked"),
                        help="break the chip model on purpose (shows the test can fail): "
                             "PLL1 never locks / nothing answers on the SCCB bus / the sensor "
                             "ignores its exposure and gain registers / the power cycle loses "
                             "what the firmware wrote to flash / (--soak) the pad never comes "
                             "back into view after the first disturbance / (--view) the "
                             "viewer's requests never reach the board")
    parser.add_argument("--fil", type=float, metavar="SECONDS",
                        help="after the boot, run firmware-in-the-loop this long (emulated)")
    parser.add_argument("--autopilot", choices=("ardupilot", "ardupilot-4.7", "px4"),
                        default="ardupilot",
                        help="FIL: the flight controller on the UART (autopilot.py)")
    parser.add_argument("--line-noise", action="store_true",
                        help="FIL: garbage bytes before a quarter of the autopilot's messages")
    parser.add_argument("--power-cycle", action="store_true",
                        help="after FIL: set a parameter over MAVLink, power-cycle the chip "
                             "(its flash kept), read it back (power_cycle.py)")
    parser.add_argument("--signing", action="store_true",
                        help="after FIL: a signing key and signed, unsigned and replayed "
                             "PARAM_SETs, a power cycle, the same checks again (signing.py)")
    parser.add_argument("--view", metavar="TOUCHDOWN",
                        help="after FIL: serve RTT channel 1 on a TCP port and record frames "
                             "from it with this touchdown binary's `view --record`, then replay "
                             "them with its `detect` (view.py)")
    parser.add_argument("--lens", metavar="TOUCHDOWN",
                        help="after FIL: a longer lens and the pad's design set with this "
                             "touchdown binary's `board` over the UART, a power cycle, both "
                             "read back (lens.py)")
    parser.add_argument("--soak", action="store_true",
                        help="FIL as a soak: line noise, autopilot reboots, parameter floods, "
                             "dropped frames and brown-outs on a seeded schedule, each "
                             "followed by checks (soak.py)")
    parser.add_argument("--soak-seed", type=int, default=1, help="the soak's schedule")
    parser.add_argument("--soak-signing", action="store_true",
                        help="the soak also sets a MAVLink 2 signing key and floods signed "
                             "and unsigned PARAM_SETs (firmware with signing only)")
    parser.add_argument("--camera", choices=("qvga", "vga"), default="qvga",
                        help="FIL: the build's frame size (feature camera-vga)")
    parser.add_argument("--frame", default=None,
                        help="FIL: the camera frame (PGM) with its truth (.txt next to it); "
                             "default: frames/ in this package")
    return parser.parse_args(argv)


def main(argv=None):
    args = parse(argv)
    if (args.view or args.lens) and (args.soak or not args.fil):
        print("--view and --lens need --fil SECONDS and no --soak", file=sys.stderr)
        return 2
    if args.lens and (args.power_cycle or args.signing):
        print("--lens leaves a longer lens set on the board, which --power-cycle and --signing "
              "do not expect: run them apart", file=sys.stderr)
        return 2
    if (args.soak or args.soak_signing) and not args.fil:
        print("--soak needs --fil SECONDS", file=sys.stderr)
        return 2
    if args.soak and (args.power_cycle or args.signing or args.line_noise or
                      args.autopilot != "ardupilot"):
        print("--soak runs against the plain ArduPilot (it adds its own noise and power "
              "cycles)", file=sys.stderr)
        return 2
    board = BOARDS[args.board]
    t0 = time.monotonic()
    elf = ElfImage(args.elf)
    fil = None
    if args.fil:
        from .fil import Fil  # needs pymavlink, which the boot test alone does not
        fil = Fil(args, board)
    machine = build_chip(elf, board, args, **(fil.chip_options() if fil else {}))
    print(f"== {args.label or args.elf} ({board.name}, {args.cpu_mhz} MHz)")
    problems = run_boot(machine, board, args)
    if fil and args.soak and not problems:
        from .soak import Soak
        soak = Soak(fil, elf, board, args)
        problems += soak.run(machine)
        machine = soak.machine  # after brown-outs, the last chip
    elif fil and not problems:
        problems += fil.run(machine)
    if fil and args.view and not problems:
        from .view import View
        problems += View(fil, elf, board, args).run(machine)
    if fil and args.lens and not problems:
        from .lens import Lens
        problems += Lens(fil, elf, board, args).run(machine)
    if fil and args.power_cycle and not problems:
        from .power_cycle import PowerCycle
        problems += PowerCycle(fil, elf, board, args).run(machine)
    if fil and args.signing and not problems:
        from .signing import Signing
        problems += Signing(fil, elf, board, args).run(machine)
    problems += report_stack(machine)
    taken = dict(sorted(machine.exc.taken.items()))
    print(f"  {machine.instructions} instructions, {machine.time_ns / 1e6:.1f} ms emulated, "
          f"interrupts taken (exception number: count) {taken or 'none'}")
    print(f"  wall time {time.monotonic() - t0:.2f} s")
    for p in problems:
        print(f"  FAIL: {p}")
    print(f"  {'PASS' if not problems else 'FAIL'}")
    return 0 if not problems else 1


if __name__ == "__main__":
    sys.exit(main())
