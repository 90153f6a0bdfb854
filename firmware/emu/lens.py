"""Stage `--lens`, the lens and the pad as board settings through a power cycle: after
firmware-in-the-loop (fil.py) a ground station on the autopilot's line sets the lens's focal
lengths (TD_CAM_FX, TD_CAM_FY: FOCAL_FACTOR times the build's) and the pad's design (TD_PAD 3,
the shipped `nested`, none of whose markers the frame shows; then TD_PAD 1, `nested-field`,
the frame's pad), the chip is powered off and on, and the lens is read back.

Why: a builder who screws in another lens or prints another shipped pad sets them as
parameters, without rebuilding; the values cross the link's PARAM_SET, the save to flash,
the restore at boot and the vision task's pipeline, and only the LANDING_TARGETs show that
the pipeline solves through the lens and searches for the pad the parameters name.

Checked: PARAM_VALUE answers each PARAM_SET; with TD_PAD 3 no LANDING_TARGET carries a
position (the frame holds no marker of `nested`); with TD_PAD 1 and the longer focal length
the targets put the pad FOCAL_FACTOR times as deep along the optical axis and where it was
across it (a marker of the same size in pixels through a longer lens is that much farther:
x and y within fil.py's tolerance of the truth's, z of FOCAL_FACTOR times the truth's); after
the power cycle PARAM_REQUEST_READ answers TD_CAM_FX with the value set and the targets are
still those of the longer lens.
"""

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from .autopilot import FIRMWARE_COMPID, FIRMWARE_SYSID
from .fil import messages_since, position_problems, timed_messages
from .power_cycle import SAVE_WAIT_NS, power_cycled

# The longer lens the ground station sets, times the build's focal length.
FOCAL_FACTOR = 1.5
# The build's focal length, pixels (firmware/src/config.rs), by frame size.
BUILT_FOCAL = {"qvga": 233.5, "vga": 467.0}
# Emulated time after a PARAM_SET before the targets are looked at, and how long they are.
SETTLE_NS = 0.4e9
WATCH_NS = 0.5e9
AFTER_BOOT_NS = 1.2e9


class Lens:
    """The stage (see the module docs)."""

    def __init__(self, fil, elf, board, args):
        self.fil, self.elf, self.board, self.args = fil, elf, board, args
        self.autopilot = fil.autopilot
        self.mav = fil.autopilot.mav
        self.focal = FOCAL_FACTOR * BUILT_FOCAL[args.camera]

    def _param_set(self, name, value):
        return self.mav.param_set_encode(FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), value,
                                         mavlink.MAV_PARAM_TYPE_REAL32).pack(self.mav)

    def run(self, machine):
        start = machine.time_ns
        pad_other_at = start + 0.1e9
        pad_back_at = pad_other_at + SETTLE_NS + WATCH_NS
        end = pad_back_at + SAVE_WAIT_NS
        sets = [(pad_other_at, self._param_set("TD_CAM_FX", self.focal)),
                (pad_other_at, self._param_set("TD_CAM_FY", self.focal)),
                (pad_other_at, self._param_set("TD_PAD", 3.0)),
                (pad_back_at, self._param_set("TD_PAD", 1.0))]
        self.autopilot.feed(machine, start + 0.05e9, end, sets)
        machine.run(end, machine.pc())
        print(f"  lens: TD_CAM_FX = TD_CAM_FY = {self.focal:g} and TD_PAD 3 at 0.1 s, TD_PAD 1 "
              f"at {(pad_back_at - start) / 1e9:.1f} s, ran {(end - start) / 1e9:.1f} s")
        problems = [machine.failure] if machine.failure else []
        if machine.finished:
            problems.append(f"stopped early: {machine.finished}")
        timed = timed_messages(machine)
        for name, value in (("TD_CAM_FX", self.focal), ("TD_PAD", 3.0), ("TD_PAD", 1.0)):
            problems += self._check_value(messages_since(timed, pad_other_at), name, value)
        other = [m for t, m in timed if pad_other_at + SETTLE_NS <= t < pad_back_at
                 and m.get_type() == "LANDING_TARGET"]
        with_position = [m for m in other if m.position_valid]
        print(f"  lens: TD_PAD 3 (nested): {len(other)} LANDING_TARGETs, {len(with_position)} "
              "with a position")
        if with_position:
            problems.append(f"{len(with_position)} LANDING_TARGETs with a position while TD_PAD "
                            "named a pad the frame does not show")
        problems += self._check_targets(messages_since(timed, pad_back_at + SETTLE_NS),
                                        "with TD_PAD 1 and the longer lens")
        if problems:
            return problems
        return self._after_power_cycle(machine)

    def _after_power_cycle(self, old):
        image = bytes(old.uc.mem_read(0x0800_0000, 2 * 1024 * 1024))
        machine, problems = power_cycled(self.fil, self.elf, self.board, self.args, image)
        if problems:
            return [f"lens, after the power cycle: {p}" for p in problems]
        start = machine.time_ns
        read_at = start + 0.3e9
        end = start + AFTER_BOOT_NS
        self.autopilot.feed(machine, start + 0.05e9, end, [(
            read_at, self.mav.param_request_read_encode(
                FIRMWARE_SYSID, FIRMWARE_COMPID, b"TD_CAM_FX", -1).pack(self.mav))])
        machine.run(end, machine.pc())
        if machine.failure:
            return [f"lens, after the power cycle: {machine.failure}"]
        if machine.finished:
            problems.append(f"lens, after the power cycle: stopped early: {machine.finished}")
        timed = timed_messages(machine)
        problems += self._check_value(messages_since(timed, read_at), "TD_CAM_FX", self.focal)
        problems += self._check_targets(messages_since(timed, start + 0.3e9),
                                        "after the power cycle")
        return problems

    def _check_value(self, messages, name, value):
        values = [m.param_value for m in messages if m.get_type() == "PARAM_VALUE"
                  and m.param_id.rstrip("\0") == name]
        if not any(abs(v - value) < 1e-3 for v in values):
            return [f"no PARAM_VALUE {name} = {value:g} (got {values})"]
        print(f"  lens: PARAM_VALUE {name} = {value:g}")
        return []

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
