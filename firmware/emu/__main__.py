"""Runs one touchdown firmware ELF on the emulated STM32H743 and prints a summary.

    python3 -m emu ELF --board nucleo|openmv [--cpu-mhz 400|480] [--fil SECONDS ...]

Exit status 0 when every check passed, 1 on a failure (the message names the pc, the function
and the address), 2 on bad usage.
"""

import argparse
import sys

from .boot import boot_test


def main(argv=None):
    parser = argparse.ArgumentParser(prog="emu", description=__doc__.split("\n")[0])
    parser.add_argument("elf")
    parser.add_argument("--board", choices=("nucleo", "openmv"), required=True)
    parser.add_argument("--cpu-mhz", type=int, choices=(400, 480), default=400)
    parser.add_argument("--label", help="name of this build in the summary")
    parser.add_argument("--spin-bound", type=int, default=100_000,
                        help="reads of one register from one pc without a change that count "
                             "as a hang")
    parser.add_argument("--inject", choices=("no-pll1rdy",),
                        help="break the chip model on purpose (shows the test can fail)")
    args = parser.parse_args(argv)
    ok = boot_test(args)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
