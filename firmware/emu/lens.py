"""Stage `--lens TOUCHDOWN`, the lens and the pad as board settings through a power cycle: after
firmware-in-the-loop (fil.py) `touchdown board` on the board's UART (bridged over TCP beside
the autopilot's messages, as a flight controller routes a ground station's: bridge.py) sets
a lens from a CAMERA.toml with FOCAL_FACTOR times the build's focal length (`set-camera`),
the pad's design (`set-pad nested`: TD_PAD 3, the shipped `nested`, none of whose markers the
frame shows; then `set-pad nested-field`: TD_PAD 1, the frame's pad), the chip is powered
off and on, and `touchdown board show` reads them back.

Why: a builder who screws in another lens or prints another shipped pad sets them as
parameters, without rebuilding; the values cross the link's PARAM_SET, the save to flash,
the restore at boot and the vision task's pipeline, and only the LANDING_TARGETs show that
the pipeline solves through the lens and searches for the pad the parameters name.

Checked: each `touchdown board` ends with its values read back; with TD_PAD 3 no
LANDING_TARGET carries a position (the frame holds no marker of `nested`); with TD_PAD 1 and the longer focal length
the targets put the pad FOCAL_FACTOR times as deep along the optical axis and where it was
across it (a marker of the same size in pixels through a longer lens is that much farther:
x and y within fil.py's tolerance of the truth's, z of FOCAL_FACTOR times the truth's); after
the power cycle `touchdown board show` answers TD_CAM_FX and TD_PAD with the values set and
the targets are still those of the longer lens.
"""

import os
import shutil
import tempfile

from . import memmap
from .bridge import run_tool
from .fil import messages_since, position_problems, timed_messages
from .power_cycle import SAVE_WAIT_NS, power_cycled

# The longer lens the ground station sets, times the build's focal length.
FOCAL_FACTOR = 1.5
# The build's focal length, pixels (firmware/src/config.rs), and frame size, by frame size.
BUILT_FOCAL = {"qvga": 233.5, "vga": 467.0}
FRAME_SIZE = {"qvga": (320, 240), "vga": (640, 400)}
# Longest emulated time one run of `touchdown board` may take.
TOOL_NS = 6e9
# Emulated time after a PARAM_SET before the targets are looked at, and how long they are.
SETTLE_NS = 0.4e9
WATCH_NS = 0.5e9
AFTER_BOOT_NS = 1.2e9


class Lens:
    """The stage (see the module docs)."""

    def __init__(self, fil, elf, board, args):
        self.fil, self.elf, self.board, self.args = fil, elf, board, args
        self.autopilot = fil.autopilot
        self.touchdown = args.lens
        self.focal = FOCAL_FACTOR * BUILT_FOCAL[args.camera]
        self.size = FRAME_SIZE[args.camera]

    def _board(self, machine, action, name):
        """`touchdown board --tcp ... ACTION` against the board's UART (bridge.py); its stdout,
        or the problem."""
        uart = machine.uart
        sent_from = len(uart.sent)

        def from_board():
            nonlocal sent_from
            data = bytes(b for _, b in uart.sent[sent_from:])
            sent_from = len(uart.sent)
            return data

        def command(port):
            return [self.touchdown, "board", "--tcp", f"127.0.0.1:{port}", "--timeout", "5"] + \
                action

        run = run_tool(machine, self.autopilot, command,
                       lambda data: uart.feed(data, machine.time_ns), from_board, TOOL_NS)
        print(f"  lens: touchdown board {' '.join(action[:1])} ({name}): exit {run.returncode} "
              f"after {(run.end_ns - run.start_ns) / 1e9:.2f} s emulated")
        if machine.failure:
            return None, run, [machine.failure]
        if run.returncode != 0 or run.timed_out:
            return None, run, [f"touchdown board {' '.join(action)}: exit {run.returncode}: "
                               f"{run.last_line(run.stderr)}"]
        return run.stdout, run, []

    def _idle(self, machine, ns):
        start = machine.time_ns
        self.autopilot.feed(machine, start, start + ns)
        machine.run(start + ns, machine.pc())

    def run(self, machine):
        work = tempfile.mkdtemp(prefix="touchdown-emu-lens-")
        try:
            return self._run(machine, work)
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def _run(self, machine, work):
        w, h = self.size
        camera = os.path.join(work, "camera.toml")
        with open(camera, "w") as f:
            f.write(f"width = {w}\nheight = {h}\nfx = {self.focal}\nfy = {self.focal}\n"
                    f"cx = {(w - 1) / 2}\ncy = {(h - 1) / 2}\n")
        out, _, problems = self._board(machine, ["set-camera", camera], "the longer lens")
        if problems:
            return problems
        if f"TD_CAM_FX = {self.focal:g}" not in out:
            return [f"touchdown board set-camera did not read back TD_CAM_FX {self.focal:g}: {out}"]
        out, run, problems = self._board(machine, ["set-pad", "nested"], "TD_PAD 3")
        if problems:
            return problems
        other_from = run.end_ns
        self._idle(machine, SETTLE_NS + WATCH_NS)
        other_to = machine.time_ns
        out, run, problems = self._board(machine, ["set-pad", "nested-field"], "TD_PAD 1")
        if problems:
            return problems
        back_from = run.end_ns
        self._idle(machine, SAVE_WAIT_NS)
        if machine.failure or machine.finished:
            return [machine.failure or f"stopped early: {machine.finished}"]
        timed = timed_messages(machine)
        other = [m for t, m in timed if other_from + SETTLE_NS <= t < other_to
                 and m.get_type() == "LANDING_TARGET"]
        with_position = [m for m in other if m.position_valid]
        print(f"  lens: TD_PAD 3 (nested): {len(other)} LANDING_TARGETs, {len(with_position)} "
              "with a position")
        if with_position:
            problems.append(f"{len(with_position)} LANDING_TARGETs with a position while TD_PAD "
                            "named a pad the frame does not show")
        problems += self._check_targets(messages_since(timed, back_from + SETTLE_NS),
                                        "with TD_PAD 1 and the longer lens")
        if problems:
            return problems
        return self._after_power_cycle(machine)

    def _after_power_cycle(self, old):
        image = bytes(old.uc.mem_read(memmap.FLASH.base, memmap.FLASH.size))
        machine, problems = power_cycled(self.fil, self.elf, self.board, self.args, image)
        if problems:
            return [f"lens, after the power cycle: {p}" for p in problems]
        out, run, problems = self._board(machine, ["show"], "after the power cycle")
        if problems:
            return [f"lens, after the power cycle: {p}" for p in problems]
        for line in (f"TD_CAM_FX = {self.focal:g}", "TD_PAD = 1"):
            if line not in out:
                problems.append(f"after the power cycle `touchdown board show` lacks {line!r}: "
                                f"{out.strip()}")
        self._idle(machine, AFTER_BOOT_NS)
        timed = timed_messages(machine)
        problems += self._check_targets(messages_since(timed, run.end_ns + SETTLE_NS),
                                        "after the power cycle")
        return problems

    def _check_targets(self, messages, when):
        targets = [m for m in messages if m.get_type() == "LANDING_TARGET"]
        if not targets:
            return [f"no LANDING_TARGET {when}"]
        want = self.autopilot.expected_target(depth_scale=FOCAL_FACTOR)
        last = targets[-1]
        print(f"  lens: LANDING_TARGET x{len(targets)} {when}, last: x {last.x:.2f} y {last.y:.2f} "
              f"z {last.z:.2f} m (expected {want['x']:.2f} {want['y']:.2f} {want['z']:.2f})")
        return position_problems(last, want, when=f" {when} (the lens {FOCAL_FACTOR:g} times "
                                                  "longer)")
