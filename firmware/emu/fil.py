"""Stage 2, firmware-in-the-loop: after the boot, the firmware runs against emulated hardware
for a given emulated time: the OV7725 on the SCCB bus (probe, reset, configuration), the DCMI
delivering a recorded frame with the firmware's pad in view (30 fps), and an ArduPilot or PX4
autopilot on the UART (autopilot.py). Everything the firmware transmits is decoded with
pymavlink: its HEARTBEATs must be well-formed and about 1 Hz, its LANDING_TARGETs must agree
with the frame's truth in the profile's frame, and PX4's TIMESYNC requests must be answered
quickly. The frame is delivered at the brightness the firmware's exposure and gain registers
give it, starting twice too bright (camera.py): the firmware's exposure loop must take its
paper out of clipping. Flash must be written only for a reason (flash.py).

The frame (`frames/*.pgm` in this package, with its truth in the `.txt` beside it) was
rendered by the simulator (`touchdown simulate`) and resampled into the firmware's own pinhole
model (`make_frame.py`), so the firmware's pose must reproduce the truth up to the detector's
pixel noise. The IWDG is modelled: a firmware that stops finishing frames is reset, which
here is a failure.
"""

import math
import os

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from .autopilot import PX4_MAX_RTT_NS, Autopilot
from .flash import BANK_SIZE, SECTOR_SIZE

FRAMES_DIR = os.path.join(os.path.dirname(__file__), "frames")
DEFAULT_FRAME = {"qvga": "nested-field-qvga.pgm", "vga": "nested-field-vga.pgm"}
# How far the firmware's pose may be from the truth: distance within this fraction, each
# position component within this fraction of the distance, the angles within this (rad).
# The autopilot reports the vehicle the frame was rendered from, so nothing but the
# detector's pixel noise separates them (measured: within 1 cm and 0.001 rad at 4.3 m): 1.5 %
# is 6.5 cm, less than a degree of attitude or mount handled wrong would move it (7.5 cm).
DISTANCE_TOLERANCE = 0.015
POSITION_TOLERANCE = 0.015
ANGLE_TOLERANCE = 0.005
# A TIMESYNC answer must come back within this: half PX4's MAX_RTT_SAMPLE, because the
# emulator runs one instruction per cycle and the chip, with its memory stalls, is slower.
TIMESYNC_RTT_LIMIT_NS = PX4_MAX_RTT_NS / 2


def read_pgm(path):
    """(width, height, bytes) of a binary 8-bit PGM."""
    with open(path, "rb") as f:
        data = f.read()
    fields, pos = [], 0
    while len(fields) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos)
            continue
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    if fields[0] != b"P5" or fields[3] != b"255":
        raise ValueError(f"{path}: not an 8-bit binary PGM")
    width, height = int(fields[1]), int(fields[2])
    pixels = data[pos + 1:pos + 1 + width * height]
    return width, height, pixels


def read_truth(path):
    """The `key = value` lines of a frame's truth file, as floats."""
    truth = {}
    with open(path) as f:
        for line in f:
            line = line.split("#")[0].strip()
            if line:
                key, value = (s.strip() for s in line.split("="))
                truth[key] = float(value)
    return truth


def position_problems(target, want, when=""):
    """How a LANDING_TARGET misses `want` (`Autopilot.expected_target`): its frame, its
    distance (within DISTANCE_TOLERANCE), each of x, y, z (within POSITION_TOLERANCE of the
    distance)."""
    d = want["distance"]
    problems = []
    if target.frame != want["frame"]:
        problems.append(f"LANDING_TARGET frame {target.frame}{when}, expected {want['frame']}")
    if abs(target.distance - d) > DISTANCE_TOLERANCE * d:
        problems.append(f"LANDING_TARGET distance {target.distance:.2f} m{when}, expected "
                        f"{d:.2f} m")
    for axis in ("x", "y", "z"):
        if abs(getattr(target, axis) - want[axis]) > POSITION_TOLERANCE * d:
            problems.append(f"LANDING_TARGET {axis} {getattr(target, axis):.2f} m{when}, "
                            f"expected {want[axis]:.2f} m")
    return problems


def timed_messages(machine):
    """(emulated time ns of its last byte, message) of everything the firmware sent, decoded
    with pymavlink."""
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    out = []
    for t, b in machine.uart.sent:
        m = mav.parse_char(bytes([b]))
        if m is not None and m.get_type() != "BAD_DATA":
            out.append((t, m))
    return out


def messages_since(timed, since_ns):
    """The messages of `timed` (timed_messages) finished from emulated time `since_ns` on."""
    return [m for t, m in timed if t >= since_ns]


class Fil:
    """One FIL run: the frame, the autopilot, the checks."""

    def __init__(self, args, board):
        self.seconds = args.fil
        name = args.frame or os.path.join(FRAMES_DIR, DEFAULT_FRAME[args.camera])
        self.frame = read_pgm(name)
        self.truth = read_truth(os.path.splitext(name)[0] + ".txt")
        self.board = board
        self.autopilot = Autopilot(args.autopilot, self.truth, line_noise=args.line_noise)

    def chip_options(self):
        return {"frames": [self.frame]}

    def run(self, machine):
        start = machine.time_ns
        end = start + self.seconds * 1e9
        self.autopilot.feed(machine, start + 0.1e9, end)
        machine.stop_at_first_idle = False
        machine.finished = None
        machine.run(end, machine.pc())
        problems = [machine.failure] if machine.failure else []
        if machine.finished:
            problems.append(f"FIL stopped early: {machine.finished}")
        print(f"  FIL: {self.seconds:g} s emulated after the boot")
        self._report_hardware(machine)
        problems += self._check_flash(machine)
        problems += self._check_exposure(machine)
        problems += self._check_led(machine, start)
        problems += self._check_link(machine)
        return problems

    def _check_flash(self, machine):
        """Flash is written only for a reason: unless the autopilot set a parameter, nothing may
        be programmed; only a sector of foreign data (the OpenMV Cam's ROMFS) erased, once."""
        flash = machine.flash
        erased = [(bank, sector) for _, bank, sector in flash.erased]
        print(f"  flash: {len(flash.programmed)} flash word(s) programmed, sectors erased "
              f"(bank, sector): {erased or 'none'}")
        problems = []
        if flash.programmed and not self.autopilot.sets_parameters():
            problems.append(f"{len(flash.programmed)} flash word(s) programmed with no "
                            "parameter changed")
        want = []
        if self.board.foreign_sector is not None:
            offset = self.board.foreign_sector - flash.banks[0].base
            want = [(offset // BANK_SIZE, offset % BANK_SIZE // SECTOR_SIZE)]
        if erased != want:
            problems.append(f"sectors erased {erased}, expected {want} (the board's foreign "
                            "data only)")
        return problems

    def _check_led(self, machine, start):
        """The heartbeat task toggles the LED every 500 ms."""
        toggles = [t for gpio in machine.gpios for t, pin, _ in gpio.changes
                   if pin == self.board.led and t >= start]
        print(f"  LED {self.board.led}: {len(toggles)} toggles")
        want = 2 * int(self.seconds)
        if want - 1 <= len(toggles) <= want + 1:
            return []
        return [f"LED {self.board.led} toggled {len(toggles)} times in {self.seconds:g} s "
                "(2 Hz expected)"]

    def _check_exposure(self, machine):
        """The firmware's exposure loop, closed through the emulated sensor (camera.py: the
        frames start twice too bright): it must set the exposure manually and bring the
        frame out of clipping (no pixel at 255: the loop holds the markers' white at 200 to
        leave the larger paper areas headroom, and a clipped level beside an edge moves it)."""
        scales = machine.dcmi.scales
        if not scales:
            return []
        brightest = max(self.frame[2])
        written = sum(1 for _, setting in machine.sensor.exposures if setting is not None)
        first, last = scales[0], scales[-1]

        clipped_first, clipped_last = (
            sum(1 for v in self.frame[2] if round(v * scale) >= 255) for scale in (first, last))
        print(f"  exposure: {written} setting(s) reached the sensor; frames at {first:.2f} -> "
              f"{last:.2f} times the file's light, its brightest pixel "
              f"{min(255, round(brightest * first))} -> {min(255, round(brightest * last))}, "
              f"clipped pixels {clipped_first} -> {clipped_last}")
        if written == 0:
            return ["the firmware never set the sensor's exposure (AEC/AGC left on)"]
        if clipped_last:
            return [f"{clipped_last} pixels still clip after {len(scales)} frames "
                    f"(x {last:.2f} in the last one)"]
        return []

    @staticmethod
    def _report_hardware(machine):
        i2c = machine.i2c.transactions
        nacks = sum(1 for _, kind, _ in i2c if kind == "nack")
        print(f"  sensor: {len(i2c)} SCCB transfers ({nacks} NACKed), {machine.sensor.writes} "
              f"register writes, {machine.sensor.resets} reset(s)")
        print(f"  DCMI: {machine.dcmi.delivered} frames delivered, {machine.dcmi.overruns} "
              f"overruns; IWDG fed {machine.iwdg.feeds} times")

    def _check_link(self, machine):
        timed = timed_messages(machine)
        messages = [m for _, m in timed]
        counts = {}
        for m in messages:
            counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
        autopilot = self.autopilot
        if autopilot.noise is not None:
            print(f"  line noise: {autopilot.garbage_bytes} garbage bytes before "
                  f"{autopilot.garbled} of the autopilot's {autopilot.fed} messages")
        print(f"  UART: {len(machine.uart.sent)} bytes at {machine.uart.baud():.0f} baud, "
              f"{len(messages)} MAVLink messages: {counts}")
        texts = sorted({m.text for m in messages if m.get_type() == "STATUSTEXT"})
        for text in texts:
            print(f"  STATUSTEXT: {text}")
        problems = self._check_heartbeats(messages)
        problems += self._check_targets(messages)
        problems += self._check_timesync_answers(machine, timed)
        return problems

    def _check_timesync_answers(self, machine, timed):
        """Every TIMESYNC request of the autopilot (PX4's, 10 a second) answered with its
        ts1 echoed and the firmware's own time in tc1, back within half PX4's MAX_RTT_SAMPLE
        (TIMESYNC_RTT_LIMIT_NS)."""
        requests = [(t, ts1) for t, ts1 in self.autopilot.timesync_requests
                    if t < machine.time_ns - PX4_MAX_RTT_NS]
        if not requests:
            return []
        answers = {m.ts1: (t, m.tc1) for t, m in timed
                   if m.get_type() == "TIMESYNC" and m.tc1 != 0}
        problems, rtts = [], []
        for sent, ts1 in requests:
            if ts1 not in answers:
                problems.append(f"the TIMESYNC request at {sent / 1e9:.3f} s was not answered")
                continue
            back, tc1 = answers[ts1]
            rtts.append(back - sent)
            if back - sent >= TIMESYNC_RTT_LIMIT_NS:
                problems.append(f"the TIMESYNC request at {sent / 1e9:.3f} s was answered after "
                                f"{(back - sent) / 1e6:.1f} ms (limit {TIMESYNC_RTT_LIMIT_NS / 1e6:g}"
                                f" ms: PX4 drops answers from {PX4_MAX_RTT_NS / 1e6:g} ms)")
            if not 0 < tc1 <= back:
                problems.append(f"TIMESYNC answer tc1 {tc1} ns is not the firmware's time "
                                f"(answered at {back:.0f} ns after reset)")
        if rtts:
            print(f"  TIMESYNC: {len(rtts)} of {len(requests)} requests answered, round trip "
                  f"{min(rtts) / 1e6:.2f} to {max(rtts) / 1e6:.2f} ms")
        return problems

    def _check_heartbeats(self, messages):
        beats = [m for m in messages if m.get_type() == "HEARTBEAT"]
        problems = []
        want = int(self.seconds)
        if not want <= len(beats) <= want + 2:
            problems.append(f"{len(beats)} HEARTBEATs in {self.seconds:g} s (1 Hz expected)")
        for m in beats[:1]:
            print(f"  HEARTBEAT: type {m.type}, autopilot {m.autopilot}, "
                  f"system_status {m.system_status}, sysid {m.get_srcSystem()}, "
                  f"compid {m.get_srcComponent()}")
            if m.type != mavlink.MAV_TYPE_ONBOARD_CONTROLLER or \
                    m.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
                problems.append(f"HEARTBEAT type/autopilot {m.type}/{m.autopilot}")
        return problems

    def _check_targets(self, messages):
        targets = [m for m in messages if m.get_type() == "LANDING_TARGET"]
        want = self.autopilot.expected_target()
        print(f"  truth: pad at x {want['x']:.2f} y {want['y']:.2f} z {want['z']:.2f} m "
              f"(frame {want['frame']}), distance {want['distance']:.2f} m, angle_x "
              f"{want['angle_x']:.3f} angle_y {want['angle_y']:.3f} rad")
        if not targets:
            return ["no LANDING_TARGET sent"]
        last = targets[-1]
        print(f"  LANDING_TARGET x{len(targets)}, last: frame {last.frame}, x {last.x:.2f} "
              f"y {last.y:.2f} z {last.z:.2f} m, distance {last.distance:.2f} m, angle_x "
              f"{last.angle_x:.3f} angle_y {last.angle_y:.3f} rad, position_valid "
              f"{last.position_valid}")
        problems = position_problems(last, want)
        for angle in ("angle_x", "angle_y"):
            if abs(getattr(last, angle) - want[angle]) > ANGLE_TOLERANCE:
                problems.append(f"LANDING_TARGET {angle} {getattr(last, angle):.3f} rad, "
                                f"truth {want[angle]:.3f} rad")
        return problems
