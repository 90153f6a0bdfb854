"""Stage 3, a parameter through a power cycle: after firmware-in-the-loop (fil.py) the emulated
autopilot sets TD_TAG_SIZE to half the built pad's size with PARAM_SET; then the chip is
powered off and on (a new emulated chip that keeps only the old one's flash), and the
autopilot reads the parameter back with PARAM_REQUEST_READ.

Why: a parameter is the one thing a user sets once and expects to keep, and its path crosses
everything FIL alone does not run: the link task's PARAM_SET handling, the debounced save
through the SAVE channel, the parameter store writing flash words through embassy's async
flash driver and the flash interrupt (flash.py), and at the next boot the scan that restores
them. Telling the firmware that the pad is printed at half size also shows that the value
reaches the per-frame path: every LANDING_TARGET after the change, and after the power cycle,
must put the pad at half the distance (the angles stay).

Checked, before the power cycle: a PARAM_VALUE with the new value answers the PARAM_SET; the
LANDING_TARGETs after it are at half the truth's distance (x, y, z likewise); the firmware
programs flash words after its save delay (flash.py fails a word programmed twice, or a
store the flash interface would refuse). After it: the boot test passes again; a PARAM_VALUE
with the new value answers PARAM_REQUEST_READ; the LANDING_TARGETs are at half the distance;
the stack stays within its reserve.
"""

import os
import tomllib

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from . import memmap
from .autopilot import FIRMWARE_COMPID, FIRMWARE_SYSID
from .boot import report_stack, run_boot
from .chip import build_chip
from .fil import messages_since, position_problems, timed_messages

PARAM = "TD_TAG_SIZE"
# The firmware's built pad (firmware/src/config.rs: core's NESTED_FIELD, which a host test
# keeps identical to this file).
PAD_FILE = os.path.join(os.path.dirname(__file__), "..", "..", "pads", "nested-field.toml")
# The save delay (core's SAVE_DEBOUNCE_US, 2 s) plus room for the flash words.
SAVE_WAIT_NS = 2.6e9
# Emulated time after the PARAM_SET and after the second boot before the checks.
SETTLE_NS = 0.5e9
AFTER_BOOT_NS = 1.2e9


def half_pad_size():
    """Half the edge of the built pad's largest marker, metres: TD_TAG_SIZE for the pad
    printed at half size."""
    with open(PAD_FILE, "rb") as f:
        layout = tomllib.load(f)
    return max(m["size"] for m in layout["marker"]) / 2


def power_cycled(fil, elf, board, args, image):
    """A new chip, all else back to reset, whose flash holds `image` (the old chip's flash as
    the power cut left it; None: as flashed), booted: (machine, boot problems), the machine
    set to run on past its first idle."""
    machine = build_chip(elf, board, args, **fil.chip_options())
    if image is not None:
        machine.uc.mem_write(memmap.FLASH.base, image)
    problems = run_boot(machine, board, args)
    machine.stop_at_first_idle = False
    machine.finished = None
    return machine, problems


def half_size_target_problems(autopilot, messages, when):
    """The last LANDING_TARGET of `messages` against the truth for the pad printed at half
    size (TD_TAG_SIZE at half the built marker)."""
    targets = [m for m in messages if m.get_type() == "LANDING_TARGET"]
    if not targets:
        return [f"no LANDING_TARGET {when}"]
    want = autopilot.expected_target(scale=0.5)
    last = targets[-1]
    print(f"  LANDING_TARGET x{len(targets)} {when}, last: distance {last.distance:.2f} m "
          f"(for the pad at half size: {want['distance']:.2f} m), x {last.x:.2f} "
          f"y {last.y:.2f} z {last.z:.2f} (expected {want['x']:.2f} {want['y']:.2f} "
          f"{want['z']:.2f})")
    return position_problems(last, want, when=f" {when} (the pad printed at half size)")


class PowerCycle:
    """The stage: `run` takes the machine FIL ran on and returns the problems found."""

    def __init__(self, fil, elf, board, args):
        self.fil, self.elf, self.board, self.args = fil, elf, board, args
        self.value = half_pad_size()
        self.autopilot = fil.autopilot
        self.mav = fil.autopilot.mav

    def run(self, machine):
        problems = self._set(machine)
        if problems:
            return problems
        return self._after_power_cycle(machine)

    def _set(self, machine):
        start = machine.time_ns
        set_at = start + 0.1e9
        end = set_at + SAVE_WAIT_NS
        self.autopilot.feed(machine, start + 0.05e9, end, [(set_at, self.mav.param_set_encode(
            FIRMWARE_SYSID, FIRMWARE_COMPID, PARAM.encode(), self.value,
            mavlink.MAV_PARAM_TYPE_REAL32).pack(self.mav))])
        written = len(machine.flash.programmed)
        machine.run(end, machine.pc())
        print(f"  power cycle: PARAM_SET {PARAM} = {self.value:g} at "
              f"{(set_at - start) / 1e9:.1f} s, ran {(end - start) / 1e9:.1f} s")
        problems = [machine.failure] if machine.failure else []
        if machine.finished:
            problems.append(f"stopped early after PARAM_SET: {machine.finished}")
        timed = timed_messages(machine)
        messages = messages_since(timed, set_at)
        for text in sorted({m.text for m in messages if m.get_type() == "STATUSTEXT"}):
            print(f"  STATUSTEXT: {text}")
        problems += self._check_value(messages, "PARAM_SET")
        problems += self._check_targets(messages_since(timed, set_at + SETTLE_NS),
                                        "after PARAM_SET")
        flash = machine.flash
        words = flash.programmed[written:]
        print(f"  flash: {len(words)} flash word(s) programmed after the PARAM_SET"
              + (f" ({words[0][1]:#010x} first, {(words[0][0] - set_at) / 1e9:.2f} s after it)"
                 if words else ""))
        if not words:
            problems.append(f"no flash word programmed {SAVE_WAIT_NS / 1e9:g} s after the "
                            "PARAM_SET (the save)")
        return problems

    def _after_power_cycle(self, old):
        """A new chip with the old one's flash (all else back to reset), booted and run."""
        if self.args.inject != "volatile-flash":
            image = bytes(old.uc.mem_read(memmap.FLASH.base, memmap.FLASH.size))
            print("  power cycle: a new chip with the old flash")
        else:
            image = None
            print("  power cycle: a new chip, its flash as flashed (--inject volatile-flash)")
        machine, problems = power_cycled(self.fil, self.elf, self.board, self.args, image)
        if problems:
            return [f"after the power cycle: {p}" for p in problems]
        start = machine.time_ns
        read_at = start + 0.3e9
        end = start + AFTER_BOOT_NS
        self.autopilot.feed(machine, start + 0.05e9, end, [(
            read_at, self.mav.param_request_read_encode(
                FIRMWARE_SYSID, FIRMWARE_COMPID, PARAM.encode(), -1).pack(self.mav))])
        machine.run(end, machine.pc())
        if machine.failure:
            return [f"after the power cycle: {machine.failure}"]
        if machine.finished:
            problems.append(f"after the power cycle: stopped early: {machine.finished}")
        timed = timed_messages(machine)
        problems += self._check_value(messages_since(timed, read_at), "PARAM_REQUEST_READ")
        problems += self._check_targets(messages_since(timed, start + 0.3e9),
                                        "after the power cycle")
        problems += [f"after the power cycle: {p}" for p in report_stack(machine)]
        return problems

    def _check_value(self, messages, asked_by):
        values = [m for m in messages if m.get_type() == "PARAM_VALUE"
                  and m.param_id.rstrip("\0") == PARAM]
        if not values:
            return [f"no PARAM_VALUE {PARAM} answered the {asked_by}"]
        got = values[0].param_value
        print(f"  PARAM_VALUE {PARAM} = {got:g} (answering the {asked_by})")
        if abs(got - self.value) > 1e-6:
            return [f"PARAM_VALUE {PARAM} {got:g} answered the {asked_by}, expected "
                    f"{self.value:g}"]
        return []

    def _check_targets(self, messages, when):
        return half_size_target_problems(self.autopilot, messages, when)
