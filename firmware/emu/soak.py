"""Stage 2b, the soak (`--soak`): firmware-in-the-loop for a long emulated time under a seeded
schedule of disturbances, each followed by checks (issue 42).

Why: the two-second FIL shows that the firmware lands on a clean line once. A flight is
minutes long, and on the way the line to the autopilot picks up noise, the autopilot
reboots, a ground station floods the parameter protocol, the camera drops frames and the
supply browns out. What must hold after each of those: the LANDING_TARGETs come back within
a few camera frames and agree with the truth, nothing piles up (no queue grows, the
stack's high-water mark settles), and no parameter that was saved is lost. Only a long run
with everything mixed shows a queue that grows by one per disturbance, or a save that a
power cut at the wrong moment destroys.

The schedule: rounds, each one of every disturbance kind in a seeded random order
(`--soak-seed`), with quiet time between them, until the emulated time is spent (the first
round always runs whole, so a short run still has one of each):

- `line-noise`: for a while every message of the autopilot comes after garbage, and
  corrupted frames (a byte flipped: the CRC fails; a frame cut short) are mixed in, among
  them a PARAM_SET whose CRC fails, which must not change its parameter.
- `autopilot-reboot`: the autopilot goes silent, then comes back with its clock restarted
  near zero (the firmware must notice the clock going back and keep sending targets).
- `param-flood`: a ground station sends PARAM_SET (valid values, out-of-range, NaN,
  non-integral, unknown names, other targets), PARAM_REQUEST_READ and PARAM_REQUEST_LIST at
  several hundred a second. Valid values go only to parameters that change nothing the
  target check compares under the ArduPilot profile (`FLOOD_SETTABLE`); every other
  parameter only gets values it must refuse. Afterwards each parameter touched reads back
  as this module's own validation of the flood says (`valid_value`, a mirror of
  core/src/params/mod.rs's table), and the debounced save reaches flash.
- `dropped-frames`: the sensor delivers nothing for a while, every other frame, or frames
  without the pad; then the pad again.
- `brown-out`: the power is cut and comes back (a new chip with the old chip's flash, as
  `kept_at_power_off` leaves it): at a random point, or, every other time, while the slot of
  a save is being programmed (after a random number of its flash words). After the boot the
  whole parameter list read back must equal what was last saved completely, or, for a cut
  during a save, the set being saved.
- `signed-flood` (`--soak-signing`, for firmware with MAVLink 2 signing): see
  `_signed_flood`.

"Resume" is measured from the disturbance's end: the last byte of the noise or of the flood
arriving, the rebooted autopilot's first HEARTBEAT arriving, the start of the sensor's first
frame after the dropped-frames window, and after a brown-out the later of the first
HEARTBEAT's arrival after the boot (the firmware chooses its profile from it) and the start of
the first frame's exposure after the boot. The count is the sensor's frame periods that ended
after that point up to the first LANDING_TARGET that agrees with the truth (`resume_frames`;
frames the firmware did not capture count): 1 means the target of the first frame that could
have one. At most `RESUME_FRAMES`, after a brown-out `COLD_RESUME_FRAMES` (a new track must be
confirmed). A stall that makes the firmware restart the camera is counted from the first
frame after the restart, which must come within the firmware's own budget
(`CAMERA_RESTART_NS`).

Throughout: every LANDING_TARGET agrees with the truth (fil.py's tolerances); the board's
HEARTBEAT keeps its 1 Hz; TIMESYNC requests (every `TIMESYNC_PROBE_NS`, exact matching by
ts1) are answered within `TIMESYNC_LIMIT_NS`, and a PARAM_REQUEST_READ probe (every
`PARAM_PROBE_NS`) within `PARAM_ANSWER_LIMIT_NS`: the firmware's transmit queue is a fixed
deque whose overflow drops, so a queue that grows shows as answers that come late or never;
the firmware's own count of events dropped because the link's channel was full
(`DROPPED_LINK_EVENTS`, read through its ELF symbol) stays where it was once the link ran;
the stack's high-water mark (the emulator paints the stack) after the warm-up (the first
minute, or the first round of a shorter run) stays within `STACK_GROWTH_BOUND` of the mark
before it. The soak stops at the first failure.
"""

import hashlib
import math
import random
import struct
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from .autopilot import FIRMWARE_COMPID, FIRMWARE_SYSID, HEARTBEAT_PERIOD_NS, STATE_PERIOD_NS
from .power_cycle import power_cycled
from .fil import ANGLE_TOLERANCE, position_problems

FRAME_NS = 1e9 / 30
# The firmware's own budget for a camera restart (firmware/src/vision.rs, "Settling and
# faults": three failed captures, power cycle, set-up, settling): from the last finished
# frame to the first after the restart, "about 0.7 s"; allowed here: that and three frame
# periods. A sensor that stalls long enough for three captures to fail is restarted, and no
# frame is taken before that is done.
CAMERA_RESTART_NS = 0.8e9
RESTART_TEXT = "camera capture failing, restarting it"
# Targets must be back within this many camera frames with the pad after a disturbance
# (issue 42)...
RESUME_FRAMES = 2
# ...but for a cold start (a brown-out: the board boots with no track of the pad) a new
# track is reported only once it is confirmed, after TrackerConfig::level()'s confirm_count
# accepted measurements (core/src/filter/tracker/mod.rs): that many frames. The pauses the
# soak makes in the pad's view stay within the tracker's lost_timeout, so the other kinds
# keep their track.
COLD_RESUME_FRAMES = 3
# The ground station's ids (a GCS, routed by the autopilot onto the board's line).
GCS_SYSID, GCS_COMPID = 255, 190
# The probes of the board's queues: TIMESYNC requests from the autopilot and a
# PARAM_REQUEST_READ from the ground station, and how soon each must be answered. The
# TIMESYNC bound is fil.py's (half PX4's MAX_RTT_SAMPLE). The parameter answer waits in the
# transmit queue behind at most its 16 entries and a LANDING_TARGET, each well under a
# millisecond at 921600 baud: a bound of a few frames leaves room for the link's 5 ms tick
# and the flood's own answers, and is far below what a queue that only grows would reach.
TIMESYNC_PROBE_NS = 250e6
PARAM_PROBE_NS = 1e9
PROBE_PARAM = "TD_RATE_HZ"
TIMESYNC_LIMIT_NS = 5e6
PARAM_ANSWER_LIMIT_NS = 50e6
# Allowed growth of the stack's high-water mark after the warm-up, bytes.
STACK_GROWTH_BOUND = 256
WARMUP_NS = 60e9
# The firmware saves parameters once they have been stable this long (core's
# SAVE_DEBOUNCE_US); the save must begin within this window after the last change.
SAVE_WINDOW_NS = (1.9e9, 2.8e9)
# Flash words programmed less than this apart belong to one save.
SAVE_GAP_NS = 50e6
# How long a brown-out keeps the board off.
POWER_OFF_NS = 50e6
# The emulator runs at most this long between samples of the board's state.
CHUNK_NS = 0.5e9
# The flood: messages a second and how long.
FLOOD_RATE = (300, 600)
FLOOD_SECONDS = (0.25, 0.5)

# The parameters the floods touch, as core/src/params/mod.rs declares them: (min, max,
# integer, zero means unset).
PARAM_RANGES = {
    "TD_PROFILE": (0, 3, True, False),
    "TD_RATE_HZ": (1, 100, True, False),
    "TD_TAG_SIZE": (0.02, 5, False, True),
    "TD_CAM_YAW": (-180, 180, False, False),
    "TD_SYSID": (1, 255, True, False),
    "TD_COMPID": (1, 255, True, False),
    "TD_BAUD": (9600, 3_000_000, True, False),
    "TD_TIME_BASE": (0, 2, True, False),
    "TD_CAM_POS_X": (-5, 5, False, False),
    "TD_CAM_POS_Y": (-5, 5, False, False),
    "TD_CAM_POS_Z": (-5, 5, False, False),
    "TD_PX4_OL_ALT": (0, 50, False, False),
    "TD_PAD_YAW": (-1, 360, False, False),
    "TD_LOCK": (0, 1, True, False),
}
# Valid values go only to these: under the ArduPilot profile none of them changes the
# BODY_FRD target the checks compare (the camera position and the outer loop are PX4's, the
# pad's bearing is the vision estimate's, the time base only time_usec's).
FLOOD_SETTABLE = ("TD_TIME_BASE", "TD_CAM_POS_X", "TD_CAM_POS_Y", "TD_CAM_POS_Z",
                  "TD_PX4_OL_ALT", "TD_PAD_YAW")

# How long a PARAM_REQUEST_LIST's answers take to go out: the board's 33 parameters, one
# every 20 ms (core's param_stream_interval_us), and room for the line.
PARAM_LIST_NS = 1.0e9

KINDS = ("line-noise", "autopilot-reboot", "param-flood", "dropped-frames", "brown-out")
# The signing clock (10 µs units since 2015-01-01) at the soak's start: a fixed date, so that
# a seed gives the same bytes; the autopilot and the ground station run it on with the
# emulated time, as with a GPS clock.
SIGNING_EPOCH_TS = (1_796_000_000 - 1_420_070_400) * 100_000
# A pseudo-parameter in the value log: the signing key the board holds (saved with the
# parameters, in the same slot).
KEY = "#key"


def f32(value):
    """`value` as the f32 a MAVLink float field carries."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def valid_value(name, value):
    """The value the firmware must store for a PARAM_SET of `name` to `value` (its f32,
    canonical zero), or None where it must refuse it (core's `params::validate`)."""
    lo, hi, integer, zero_unset = PARAM_RANGES[name]
    v = f32(value)
    if not math.isfinite(v):
        return None
    if zero_unset and v == 0.0:
        return 0.0
    if not f32(lo) <= v <= f32(hi):
        return None
    if integer and math.trunc(v) != v:
        return None
    return 0.0 if v == 0.0 else v


def invalid_value(rng, name):
    """A value `valid_value` refuses for `name`."""
    lo, hi, integer, zero_unset = PARAM_RANGES[name]
    span = hi - lo
    choices = [hi + rng.uniform(0.01, 2) * span + 1, lo - rng.uniform(0.01, 2) * span - 1,
               math.nan, math.inf, -math.inf]
    if integer:
        choices.append(math.floor(rng.uniform(lo, hi)) + 0.5)
    if zero_unset:
        choices.append(lo / 2)
    value = rng.choice(choices)
    assert valid_value(name, value) is None
    return value


def a_valid_value(rng, name):
    lo, hi, integer, _ = PARAM_RANGES[name]
    value = rng.uniform(lo, hi)
    return float(round(value)) if integer else round(value, 3)


def resume_frames(deliveries, targets_ok, t_end, period=FRAME_NS):
    """(frames, ns) from `t_end` to the first good target of a frame that ended after it:
    `deliveries` (end ns, start ns, kind) of the frames the camera delivered, `targets_ok` the
    send times of the LANDING_TARGETs that agree with the truth. A target sent before the
    first frame with the pad delivered after `t_end` ended is an older frame's and does not
    count. frames counts the sensor's frame periods that ended after `t_end` up to the
    target, on the grid of that first frame, whether the firmware captured them or not (a
    frame it missed is a frame late). (None, None) if none came."""
    first_frame = next((end for end, _, kind in deliveries if kind == "pad" and end > t_end),
                       None)
    if first_frame is None:
        return None, None
    first = next((t for t in targets_ok if t >= first_frame), None)
    if first is None:
        return None, None
    # The first frame end of the sensor's grid after t_end.
    grid_end = first_frame - math.floor((first_frame - t_end) / period - 1e-9) * period
    return math.floor((first - grid_end) / period) + 1, first - t_end


def signature_status(key, frame, newest):
    """("sig_ok" | "unsigned" | "bad_sig" | "behind", timestamp) of a MAVLink frame (bytes)
    checked against `key`: MAVLink 2's signature is the first 6 bytes of SHA-256 over the key
    and the frame up to the signature's last 6 bytes (link id and timestamp included);
    "behind" is a valid signature whose timestamp is not newer than `newest`, which a
    receiver applying the replay rule drops."""
    if frame[0] != 0xFD or not frame[2] & 1:
        return "unsigned", None
    timestamp = int.from_bytes(frame[-12:-6], "little")
    if hashlib.sha256(key + frame[:-6]).digest()[:6] != frame[-6:]:
        return "bad_sig", timestamp
    if timestamp <= newest:
        return "behind", timestamp
    return "sig_ok", timestamp


class SoakFailure(Exception):
    """The emulated chip failed (a fault, a watchdog reset...): the soak cannot go on."""


class SoakStop(Exception):
    """A check failed: the soak stops there (its figures up to then are printed)."""


class Soak:
    """One soak run: `run` takes the booted machine and returns the problems found."""

    def __init__(self, fil, elf, board, args):
        self.fil, self.elf, self.board, self.args = fil, elf, board, args
        self.seconds = args.fil
        self.seed = args.soak_seed
        self.rng = random.Random(self.seed)
        self.noise_rng = random.Random(self.seed + 1)
        self.ap = fil.autopilot
        self.gcs = mavlink.MAVLink(None, srcSystem=GCS_SYSID, srcComponent=GCS_COMPID)
        self.signing = args.soak_signing
        self.key = None  # the signing key once the board has one
        self.problems = []
        self.machine = None
        self.base = 0.0  # global ns at the current machine's time 0
        self.boots = 1
        self.fed_until = 0.0
        self.recent_sends = []  # (g, bytes, tag) fed lately (see `_feed`)
        self.signed_writes = []  # (g, frame, name, value) of the last signed PARAM_SETs
        self.next_hb = self.next_state = self.next_ts_probe = self.next_param_probe = 0.0
        self.silent = []  # (g0, g1): the autopilot sends nothing
        self.noisy = []  # (g0, g1): garbage before every autopilot message
        self.frame_plan = []  # (g0, g1, "skip" | "blank" | "sparse")
        self.no_param_probe = []  # (g0, g1): floods, when a PARAM_VALUE may answer others
        self.rx = []  # (g, message) the board sent
        self.hb_arrivals = []  # g of each autopilot HEARTBEAT's last byte
        self.deliveries = []  # (end g, start g, kind) of the camera's frames
        self.ts_probes = {}  # ts1 -> g of arrival
        self.param_probes = []  # g of arrival
        self.arrivals = {}  # tag -> g of arrival
        self.values = {}  # name -> the board's value, as its PARAM_VALUEs said
        self.value_log = []  # (g, name, value)
        self.saved = None  # the values of the last complete save (as the board had them)
        self.saved_at = 0.0  # when `saved` was taken
        self.cuts = []  # g of each brown-out's power cut
        self.param_count = None
        self.saves = []  # [first word g, last word g, words]
        self.words_per_save = None
        self.stack_marks = []  # (g, boot, mark)
        self.dropped_events = []  # (g, boot, count)
        self.results = []  # dict per disturbance
        self.bad_targets = 0
        self.first_bad = []
        # The board's frames once it has a key: validly signed and newer than every earlier
        # one, unsigned, with a bad signature, validly signed but not newer (`_count_signature`).
        self.signed = {"sig_ok": 0, "unsigned": 0, "bad_sig": 0, "behind": 0}
        self.board_timestamp = 0
        self.behind_until = None
        self.first_round_end = None
        self.results_from = None  # the first disturbance's start
        self.stopped = False
        self.stack_peak = 0
        self.stack_rises = []  # (g, new peak, the disturbance under way or None)
        self.current_kind = None
        # (cut g, name, taken, its save completed) of each replay after a brown-out.
        self.replays = []

    # --- global time, the line, the board's output -------------------------------------

    def now(self):
        return self.base + self.machine.time_ns

    def _attach(self, machine):
        """Hooks the soak's models into a (new) machine."""
        self.machine = machine
        machine.stop_at_first_idle = False
        machine.finished = None
        machine.dcmi.schedule = self._frame_kind
        width, height, pixels = self.fil.frame
        mean = sum(pixels) // len(pixels)
        machine.dcmi.blank_frame = (width, height, bytes([mean]) * len(pixels))
        self._rx_parser = mavlink.MAVLink(None)
        self._rx_parser.robust_parsing = True
        self._rx_pos = 0
        self._dcmi_pos = 0
        self._flash_pos = 0
        self._dropped_addr = self.elf.symbols.get(self._symbol("DROPPED_LINK_EVENTS"))

    def _symbol(self, static):
        from .elfimage import demangle
        for name in self.elf.symbols:
            if demangle(name) == f"touchdown_firmware::channels::{static}":
                return name
        return None

    def _frame_kind(self, start_ns):
        g = self.base + start_ns
        if self.args.inject == "pad-lost" and self.results_from is not None and \
                g >= self.results_from:
            return "blank"
        for g0, g1, kind in self.frame_plan:
            if g0 <= g < g1:
                if kind == "sparse":
                    return "skip" if int(g // FRAME_NS) % 2 else None
                return kind
        return None

    def _in(self, windows, g):
        return any(g0 <= g < g1 for g0, g1 in windows)

    def _garbage(self):
        rng = self.noise_rng
        garbage = bytearray(rng.randbytes(rng.randint(1, 40)))
        if rng.random() < 0.5:
            garbage[rng.randrange(len(garbage))] = rng.choice((0xFD, 0xFE))
        return bytes(garbage)

    def _autopilot_messages(self, g0, g1):
        """(g, bytes, tag) of what the autopilot sends in [g0, g1) (its own schedule, in
        global time, kept through brown-outs of the board)."""
        out = []
        ap = self.ap
        while self.next_hb < g1:
            g = self.next_hb
            self.next_hb += HEARTBEAT_PERIOD_NS
            if g >= g0 and not self._in(self.silent, g):
                out.append((g, self._autopilot_pack(ap.heartbeat), "hb"))
        while self.next_state < g1:
            g = self.next_state
            self.next_state += STATE_PERIOD_NS
            if g >= g0 and not self._in(self.silent, g):
                out.append((g, self._autopilot_pack(ap._attitude, g), None))
        while self.next_ts_probe < g1:
            g = self.next_ts_probe
            self.next_ts_probe += TIMESYNC_PROBE_NS
            if g >= g0 and not self._in(self.silent, g):
                ts1 = int(g) + 1
                out.append((g + 0.3e6, self._pack(ap.mav.timesync_encode(0, ts1), ap.mav),
                            ("ts", ts1)))
        while self.next_param_probe < g1:
            g = self.next_param_probe
            self.next_param_probe += PARAM_PROBE_NS
            if g >= g0:
                # Unsigned: reading stays open with a key.
                out.append((g + 0.6e6, self._pack(self.gcs.param_request_read_encode(
                    FIRMWARE_SYSID, FIRMWARE_COMPID, PROBE_PARAM.encode(), -1), self.gcs),
                    ("param", g)))
        return out

    def _autopilot_pack(self, build, *args):
        """The autopilot's message from `build(*args)` (which packs with its MAVLink object),
        packed when fed: signed, once it shares the board's key, with a timestamp that runs
        with the emulated time (ArduPilot signs every frame once it has a key)."""
        def pack(g):
            mav = self.ap.mav
            if mav.signing.sign_outgoing:
                mav.signing.timestamp = max(mav.signing.timestamp,
                                            SIGNING_EPOCH_TS + int(g / 1e4))
            return build(*args)
        return pack

    def _pack(self, message, mav=None, keep=None, corrupt=None):
        """`message` to be packed when it is fed at global time g (`_feed` calls the result
        with g): by `mav`, or the ground station (signed once the board has a key, as a
        ground station that set it does). Signed frames take a timestamp that runs with the
        emulated time; the frame is appended to `keep`; `corrupt(bytes)` may break it."""
        def pack(g):
            writer = mav or self._writer()
            if writer.signing.sign_outgoing:
                writer.signing.timestamp = max(writer.signing.timestamp,
                                               SIGNING_EPOCH_TS + int(g / 1e4))
            data = message.pack(writer)
            if keep is not None:
                keep.append(data)
            # (A frame broken on purpose never reached the board as a write.)
            if writer is getattr(self, "signer", None) and message.get_type() == "PARAM_SET" \
                    and corrupt is None:
                name = message.param_id
                name = (name.decode() if isinstance(name, bytes) else name).rstrip("\0")
                self.signed_writes = self.signed_writes[-20:] + [
                    (g, data, name, message.param_value)]
            return corrupt(data) if corrupt else data
        return pack

    def _writer(self):
        return self.signer if self.key is not None else self.gcs

    def _feed(self, until_g, extra=(), sent=()):
        """Puts everything sent in [fed_until, until_g) on the board's receive line, and
        `sent` (g, bytes, tag), sent already (`_brown_out`), as it is."""
        sends = self._autopilot_messages(self.fed_until, until_g) + list(extra)
        sends = [(g, data, tag, False) for g, data, tag in sends] + \
            [(g, data, tag, True) for g, data, tag in sent]
        sends.sort(key=lambda s: s[0])
        uart = self.machine.uart
        for g, data, tag, as_sent in sends:
            if not as_sent:
                if callable(data):
                    data = data(g)
                # Garbage goes before the autopilot's own messages and the broken frames,
                # not before the probes, which measure the queues, not the noise.
                if self._in(self.noisy, g) and tag in (None, "hb"):
                    data = self._garbage() + data
                # Kept while the board could still lose them to a brown-out: a frame is
                # packed (and signed) when it is fed, which is ahead of the board's time.
                self.recent_sends.append((g, data, tag))
            uart.feed(data, max(g - self.base, self.machine.time_ns))
            arrival = self.base + uart.line[-1][0] if uart.line else g
            if tag == "hb":
                self.hb_arrivals.append(arrival)
            elif isinstance(tag, tuple) and tag[0] == "ts":
                self.ts_probes[tag[1]] = arrival
            elif isinstance(tag, tuple) and tag[0] == "param":
                if not self._in(self.no_param_probe, g):
                    self.param_probes.append(arrival)
            elif isinstance(tag, str):
                self.arrivals[tag] = arrival
        self.fed_until = max(self.fed_until, until_g)
        horizon = self.now() - 0.1e9
        if self.recent_sends and self.recent_sends[0][0] < horizon:
            self.recent_sends = [s for s in self.recent_sends if s[0] >= horizon]

    def _advance(self, until_g, extra=()):
        """Runs the board to global time `until_g` with the line fed; True when a brown-out
        (`_brown_out`'s flash hook) ended it early."""
        self._feed(until_g, extra)
        machine = self.machine
        while self.now() < until_g:
            chunk_end = min(until_g, self.now() + CHUNK_NS)
            machine.run(chunk_end - self.base, machine.pc())
            self._collect()
            if machine.failure:
                raise SoakFailure(f"at {self.now() / 1e9:.3f} s (boot {self.boots}): "
                                  f"{machine.failure}")
            if machine.finished == "brown-out":
                return True
            if machine.finished:
                raise SoakFailure(f"at {self.now() / 1e9:.3f} s: stopped: {machine.finished}")
        return False

    def _collect(self):
        """Takes in what the board sent and what the camera and the flash did since the
        last call, and samples the stack and the link's dropped-event count."""
        machine = self.machine
        sent = machine.uart.sent
        parser = self._rx_parser
        for t, byte in sent[self._rx_pos:]:
            m = parser.parse_char(bytes([byte]))
            if m is None:
                continue
            if m.get_type() == "BAD_DATA":
                continue
            g = self.base + t
            self.rx.append((g, m))
            signature_ok = self._count_signature(g, m)
            if m.get_type() == "PARAM_VALUE":
                name = m.param_id.rstrip("\0")
                self.values[name] = m.param_value
                self.value_log.append((g, name, m.param_value))
            elif m.get_type() == "LANDING_TARGET":
                self._check_target(g, m, signature_ok)
        self._rx_pos = len(sent)
        for end, start, kind in machine.dcmi.deliveries[self._dcmi_pos:]:
            self.deliveries.append((self.base + end, self.base + start, kind))
        self._dcmi_pos = len(machine.dcmi.deliveries)
        for t, _ in machine.flash.programmed[self._flash_pos:]:
            g = self.base + t
            if self.saves and g - self.saves[-1][1] < SAVE_GAP_NS:
                self.saves[-1][1] = g
                self.saves[-1][2] += 1
            else:
                self.saves.append([g, g, 1])
        self._flash_pos = len(machine.flash.programmed)
        g = self.now()
        mark = machine.stack_high_water()
        if mark > self.stack_peak:
            self.stack_peak = mark
            self.stack_rises.append((g, mark, self.current_kind))
        self.stack_marks.append((g, self.boots, mark))
        if self._dropped_addr is not None:
            count = int.from_bytes(machine.uc.mem_read(self._dropped_addr, 4), "little")
            self.dropped_events.append((g, self.boots, count))

    def _check_target(self, g, target, signature_ok=True):
        want = self.ap.expected_target()
        problems = position_problems(target, want)
        for angle in ("angle_x", "angle_y"):
            if abs(getattr(target, angle) - want[angle]) > ANGLE_TOLERANCE:
                problems.append(f"LANDING_TARGET {angle} {getattr(target, angle):.3f} rad, "
                                f"truth {want[angle]:.3f}")
        if problems:
            self.bad_targets += 1
            if len(self.first_bad) < 3:
                self.first_bad.append(f"at {g / 1e9:.3f} s: {'; '.join(problems)}")
        elif signature_ok:
            # (With a key, a target the autopilot would drop for its signature is no target.)
            self.good_targets.append(g)

    def _answers(self, name, since_g):
        """The board's PARAM_VALUEs of `name` sent from `since_g` on: [(g, value)]."""
        return [(g, v) for g, n, v in self.value_log if n == name and g >= since_g]

    def _values_at(self, g_at):
        """The board's parameter values at `g_at`, from its PARAM_VALUEs up to then."""
        values = {}
        for g, name, value in self.value_log:
            if g > g_at:
                break
            values[name] = value
        return values

    # --- the run ------------------------------------------------------------------------

    def run(self, machine):
        self.good_targets = []
        self._attach(machine)
        self.start = self.now()
        self.fed_until = self.start
        self.next_hb = self.next_state = self.start + 0.1e9
        self.next_ts_probe = self.start + 0.35e9
        self.next_param_probe = self.start + 0.55e9
        end = self.start + self.seconds * 1e9
        wall = time.monotonic()
        try:
            self._advance(self.start + 1.0e9)
            self.saved = self._read_all("at the start")
            self.saved_at = self.now()
            # The mount calibration only reports (TD_CAM_CAL 1): the camera repeats one frame,
            # whose detector error a calibration would take for the mount's (it applies some
            # 0.4 degrees of roll after about ten seconds, and the targets leave the truth of
            # the nominal mount the frame was rendered with).
            g = self.now()
            self._advance(g + 0.1e9, [(g, self._set_param("TD_CAM_CAL", 1.0), None)])
            if self.values.get("TD_CAM_CAL") != 1.0:
                self.problems.append("TD_CAM_CAL 1 not taken at the start")
            kinds = list(KINDS) + (["signed-flood"] if self.signing else [])
            first_round = True
            while first_round or self.now() < end - 2e9:
                order = kinds[:]
                self.rng.shuffle(order)
                if "signed-flood" in order:
                    # The key, once set, stays; the kinds before it run unsigned.
                    order.remove("signed-flood")
                    order.append("signed-flood")
                for kind in order:
                    if not first_round and self.now() >= end - 2e9:
                        break
                    self._advance(self.now() + self.rng.uniform(0.2, 0.5) * 1e9)
                    self._disturb(kind)
                    if self.problems:
                        raise SoakStop()
                first_round = False
                if self.first_round_end is None:
                    self.first_round_end = self.now()
            if self.now() < end:
                self._advance(end)
        except SoakFailure as e:
            self.problems.append(str(e))
        except SoakStop:
            print("  soak: stopped at the first failure")
            self.stopped = True
        self.wall = time.monotonic() - wall
        self._final_checks()
        self._summary()
        return self.problems

    def _disturb(self, kind):
        g0 = self.now()
        if self.results_from is None:
            self.results_from = g0
        stack_before = max(m for _, _, m in self.stack_marks[-1:]) if self.stack_marks else 0
        result = {"kind": kind, "start": g0, "note": ""}
        self.current_kind = kind
        getattr(self, "_" + kind.replace("-", "_"))(result)
        self.current_kind = None
        result["stack"] = max((m for g, _, m in self.stack_marks if g >= g0), default=0)
        result["stack_before"] = stack_before
        frames, ns = resume_frames(self.deliveries, self.good_targets, result["end"])
        result["resume_frames"], result["resume_ns"] = frames, ns
        window = (g0, self.now())
        rtts = [self._ts_rtt(ts1, arrival) for ts1, arrival in self.ts_probes.items()
                if window[0] <= arrival < window[1]]
        result["timesync_ns"] = max((r for r in rtts if r is not None), default=None)
        gaps = [b - a for a, b in zip(self.good_targets, self.good_targets[1:])
                if a >= g0 and b <= self.now()]
        result["gap_ns"] = max(gaps, default=None)
        self.results.append(result)
        where = f"{kind} at {g0 / 1e9:.2f} s ({result['note']})"
        if frames is None:
            self.problems.append(f"{where}: no LANDING_TARGET after it")
        elif frames > (COLD_RESUME_FRAMES if kind == "brown-out" else RESUME_FRAMES):
            self.problems.append(f"{where}: targets resumed after {frames} frames "
                                 f"({ns / 1e6:.0f} ms), more than "
                                 f"{COLD_RESUME_FRAMES if kind == 'brown-out' else RESUME_FRAMES}")
        print(f"  soak {g0 / 1e9:7.2f} s: {kind:16s} {result['note']}; resumed after "
              f"{frames if frames is not None else '-'} frame(s)"
              + (f" ({ns / 1e6:.0f} ms)" if ns is not None else ""), flush=True)

    def _ts_rtt(self, ts1, arrival):
        for g, m in self._rx_since(arrival):
            if m.get_type() == "TIMESYNC" and m.tc1 != 0 and m.ts1 == ts1:
                return g - arrival
        return None

    def _rx_since(self, g0):
        """The board's messages from `g0` on (binary search: `rx` is in time order)."""
        lo, hi = 0, len(self.rx)
        while lo < hi:
            mid = (lo + hi) // 2
            if self.rx[mid][0] < g0:
                lo = mid + 1
            else:
                hi = mid
        return self.rx[lo:]

    # --- the disturbances ---------------------------------------------------------------

    def _line_noise(self, result):
        rng = self.rng
        g0 = self.now() + 0.02e9
        g1 = g0 + rng.uniform(0.2, 0.8) * 1e9
        self.noisy.append((g0, g1))
        extra, t = [], g0
        # A PARAM_SET with a flipped byte: its CRC fails, the value must not change.
        name = rng.choice(FLOOD_SETTABLE)
        old = self.values.get(name)
        new = a_valid_value(rng, name)
        while valid_value(name, new) == old:
            new = a_valid_value(rng, name)
        at, bit = rng.randrange(10, 30), 1 << rng.randrange(8)

        def flip(data):
            broken = bytearray(data)
            broken[at % (len(broken) - 2)] ^= bit
            return bytes(broken)
        extra.append((g0 + rng.uniform(0.1, 0.9) * (g1 - g0), self._pack(self.gcs.param_set_encode(
            FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), new,
            mavlink.MAV_PARAM_TYPE_REAL32), corrupt=flip), None))
        while t < g1:
            t += rng.uniform(5e6, 40e6)
            frame = bytearray(self.ap._attitude(t))
            if rng.random() < 0.5:
                frame[rng.randrange(1, len(frame))] ^= 0xFF  # a corrupted byte
            else:
                frame = frame[:rng.randrange(1, len(frame))]  # cut short
            extra.append((t, bytes(frame), None))
        # (The broken attitude frames are unsigned even with a key: the CRC fails first.)
        extra.append((g1, b"", "noise-end"))
        self._advance(g1 + 0.3e9, extra)
        result["end"] = self.arrivals["noise-end"]
        read = self.now()
        self._advance(read + 0.2e9, [(read, self._pack(self.gcs.param_request_read_encode(
            FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), -1), self.gcs), None)])
        answers = self._answers(name, read)
        if not answers or answers[0][1] != old:
            self.problems.append(f"line noise at {g0 / 1e9:.2f} s: {name} reads "
                                 f"{answers[0][1] if answers else 'nothing'} after a PARAM_SET "
                                 f"with a broken CRC, expected {old}")
        result["note"] = f"{(g1 - g0) / 1e9:.2f} s, {len(extra) - 1} broken frames"

    def _autopilot_reboot(self, result):
        rng = self.rng
        g0 = self.now() + 0.02e9
        pause = rng.uniform(0.3, 1.5) * 1e9
        self.silent.append((g0, g0 + pause))
        # Its clock restarts: at the end of the pause it reads the pause's length or less.
        self.ap.booted_before_ms = -int((g0 + rng.uniform(0, 0.9) * pause) / 1e6)
        # Its schedule restarts with it: the first HEARTBEAT right after the pause.
        self.next_hb = g0 + pause
        self.next_state = g0 + pause + 5e6
        before = len(self.hb_arrivals)
        self._advance(g0 + pause + 0.6e9)
        result["end"] = next((a for a in self.hb_arrivals[before:] if a >= g0 + pause), self.now())
        result["note"] = f"silent {pause / 1e9:.2f} s"

    def _param_flood(self, result):
        rng = self.rng
        g0 = self.now() + 0.02e9
        rate = rng.uniform(*FLOOD_RATE)
        count = int(rate * rng.uniform(*FLOOD_SECONDS))
        model = dict(self.values)
        changed_at_index = None
        extra, kinds = [], {}
        for i in range(count):
            g = g0 + i * 1e9 / rate
            r = rng.random()
            if r < 0.45:
                name = rng.choice(FLOOD_SETTABLE)
                value = a_valid_value(rng, name)
                # With a key every signed write the board applies also moves the key's saved
                # timestamp on (a parameter change: the debounce starts again).
                if valid_value(name, value) != model.get(name) or self.key is not None:
                    changed_at_index = i
                model[name] = valid_value(name, value)
                kind = "valid"
            elif r < 0.65:
                name = rng.choice(sorted(PARAM_RANGES))
                value = invalid_value(rng, name)
                kind = "refused"
                if self.key is not None:
                    changed_at_index = i
            elif r < 0.72:
                name = rng.choice(("TD_NOPE", "TD_PROFILE_", "SYSID_THISMAV", "TD_RATE_H"))
                value = 1.0
                kind = "unknown"
            elif r < 0.77:
                # Addressed to another component: not ours to apply.
                name = rng.choice(FLOOD_SETTABLE)
                extra.append((g, self._pack(self.gcs.param_set_encode(
                    FIRMWARE_SYSID, rng.choice((1, 190, 192)), name.encode(),
                    a_valid_value(rng, name), mavlink.MAV_PARAM_TYPE_REAL32)), None))
                kinds["other target"] = kinds.get("other target", 0) + 1
                continue
            elif r < 0.95:
                if rng.random() < 0.5:
                    msg = self.gcs.param_request_read_encode(
                        FIRMWARE_SYSID, FIRMWARE_COMPID, b"", rng.randrange(0, 30))
                else:
                    msg = self.gcs.param_request_read_encode(
                        FIRMWARE_SYSID, FIRMWARE_COMPID,
                        rng.choice(sorted(PARAM_RANGES)).encode(), -1)
                extra.append((g, self._pack(msg), None))
                kinds["read"] = kinds.get("read", 0) + 1
                continue
            else:
                extra.append((g, self._pack(self.gcs.param_request_list_encode(
                    FIRMWARE_SYSID, FIRMWARE_COMPID)), None))
                kinds["list"] = kinds.get("list", 0) + 1
                continue
            kinds[kind] = kinds.get(kind, 0) + 1
            extra.append((g, self._pack(self.gcs.param_set_encode(
                FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), value,
                mavlink.MAV_PARAM_TYPE_REAL32)), ("change" if i == changed_at_index else None)))
        g1 = g0 + count * 1e9 / rate
        extra.append((g1, b"", "flood-end"))
        # While the flood's answers and list streams go out, a probe's PARAM_VALUE could be
        # another's: the flood's own read-back stands for them.
        self.no_param_probe.append((g0, g1 + PARAM_LIST_NS))
        self._advance(g1 + PARAM_LIST_NS, extra)
        result["end"] = self.arrivals["flood-end"]
        changed_at = self.arrivals.get("change") if changed_at_index is not None else None
        self.arrivals.pop("change", None)
        problems = self._read_back(model, sorted(PARAM_RANGES), "after the flood")
        if changed_at is not None:
            self._advance(changed_at + SAVE_WINDOW_NS[1] + 0.1e9)
            problems += self._check_save(changed_at, "the flood")
        self.problems += [f"param flood at {g0 / 1e9:.2f} s: {p}" for p in problems]
        result["note"] = (f"{count} messages at {rate:.0f}/s: "
                          + ", ".join(f"{v} {k}" for k, v in sorted(kinds.items())))
        result["answer_ns"] = self.last_read_back_ns

    def _read_back(self, model, names, when):
        """Asks for each of `names` with PARAM_REQUEST_READ; each answer must equal
        `model`'s value. Records the slowest answer in `last_read_back_ns`."""
        g = self.now()
        extra = []
        for i, name in enumerate(names):
            extra.append((g + i * 0.5e6, self._pack(self.gcs.param_request_read_encode(
                FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), -1), self.gcs), f"read {name}"))
        self._advance(g + 0.3e9, extra)
        problems, worst = [], 0.0
        for name in names:
            asked = self.arrivals.pop(f"read {name}")
            answers = self._answers(name, asked)
            if not answers:
                problems.append(f"no PARAM_VALUE {name} answered its PARAM_REQUEST_READ {when}")
                continue
            worst = max(worst, answers[0][0] - asked)
            if model.get(name) is not None and answers[0][1] != model[name]:
                problems.append(f"{name} reads {answers[0][1]} {when}, expected {model[name]}")
        self.last_read_back_ns = worst
        return problems

    def _check_save(self, changed_at, what):
        """A save must begin within SAVE_WINDOW_NS of the last change and finish; it then
        holds the board's values (`saved`)."""
        saves = [s for s in self.saves if s[0] >= changed_at]
        if not saves:
            return [f"no flash word programmed {SAVE_WINDOW_NS[1] / 1e9:g} s after {what}'s "
                    "last change (the save)"]
        first, last, words = saves[0]
        problems = []
        if not SAVE_WINDOW_NS[0] <= first - changed_at <= SAVE_WINDOW_NS[1]:
            problems.append(f"the save began {(first - changed_at) / 1e9:.2f} s after the last "
                            "change")
        if self.words_per_save is None:
            self.words_per_save = words
        self.saved, self.saved_at = self._values_at(first), first
        return problems

    def _read_all(self, when):
        """PARAM_REQUEST_LIST: every parameter, as the board now has it; returns the values."""
        g = self.now()
        self._advance(g + PARAM_LIST_NS, [(g, self._pack(self.gcs.param_request_list_encode(
            FIRMWARE_SYSID, FIRMWARE_COMPID), self.gcs), "list")])
        asked = self.arrivals.pop("list")
        got = {}
        for t, name, value in self.value_log:
            if t >= asked and name not in got:
                got[name] = value
        if self.param_count is None:
            self.param_count = len(got)
            if len(got) < len(PARAM_RANGES):
                self.problems.append(f"PARAM_REQUEST_LIST {when}: {len(got)} parameters "
                                     "answered")
        elif len(got) != self.param_count:
            self.problems.append(f"PARAM_REQUEST_LIST {when}: {len(got)} parameters answered, "
                                 f"{self.param_count} at the start")
        return got

    def _dropped_frames(self, result):
        rng = self.rng
        g0 = self.now() + 0.02e9
        kind = rng.choice(("skip", "sparse", "blank"))
        length = rng.uniform(0.2, 0.8) * 1e9
        self.frame_plan.append((g0, g0 + length, kind))
        self._advance(g0 + length + 0.4e9)
        # From the sensor delivering the pad again: the start of its first frame that
        # starts after the window (on the grid of the frames before it)...
        ref = max((start for _, start, _ in self.deliveries if start < g0), default=g0)
        result["end"] = ref + math.ceil((g0 + length - ref) / FRAME_NS) * FRAME_NS
        result["note"] = {"skip": "no frames", "sparse": "every other frame dropped",
                          "blank": "frames without the pad"}[kind] + f" for {length / 1e9:.2f} s"
        restart = next((g for g, m in self._rx_since(g0) if m.get_type() == "STATUSTEXT"
                        and RESTART_TEXT in m.text), None)
        if restart is not None:
            # ...but a stall that made the firmware restart the camera is counted from the
            # first frame after the restart; the restart itself must keep to its budget.
            self._advance(restart + CAMERA_RESTART_NS + 0.4e9)
            last = max((end for end, _, k in self.deliveries if end < g0), default=g0)
            first = next((end for end, _, k in self.deliveries if end > restart), None)
            result["end"] = first - FRAME_NS if first is not None else self.now()
            taken = (first - last) / 1e6 if first is not None else math.inf
            result["note"] += (f"; the camera restarted: {taken:.0f} ms from the last frame "
                               "before the stall to the first after the restart")
            # Due by the later of the budget and two frames after the sensor is back.
            due = max(last + CAMERA_RESTART_NS, g0 + length + 2 * FRAME_NS)
            if first is None or first > due:
                self.problems.append(f"dropped frames at {g0 / 1e9:.2f} s: the camera restart "
                                     f"took {taken:.0f} ms from the last frame to the next "
                                     f"(budget {CAMERA_RESTART_NS / 1e6:.0f} ms, or two frames "
                                     "after the sensor is back)")

    def _brown_out(self, result):
        rng = self.rng
        mid_save = sum(1 for r in self.results if r["kind"] == "brown-out") % 2 == 0
        machine = self.machine
        if mid_save:
            name = rng.choice(FLOOD_SETTABLE)
            value = a_valid_value(rng, name)
            while valid_value(name, value) == self.values.get(name):
                value = a_valid_value(rng, name)
            g = self.now() + 0.02e9
            self._advance(g + 1.8e9, [(g, self._pack(self.gcs.param_set_encode(
                FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), value,
                mavlink.MAV_PARAM_TYPE_REAL32)), None)])
            words = self.words_per_save or 8
            cut_after = rng.randint(1, max(1, words - 1))
            before = len(machine.flash.programmed)
            flash_advance = machine.flash.advance

            def advance_then_cut(now_ns):
                flash_advance(now_ns)
                if len(machine.flash.programmed) >= before + cut_after:
                    machine.finish("brown-out")
            machine.flash.advance = advance_then_cut
            cut = self._advance(self.now() + 1.2e9)
            note = (f"cut after {len(machine.flash.programmed) - before} flash word(s) of the "
                    f"save of {name}" if cut else f"the save of {name} was not seen: cut after it")
        else:
            self._advance(self.now() + rng.uniform(0.05, 1.0) * 1e9)
            note = "at a random point"
        g_cut = self.now()
        self.cuts.append(g_cut)
        # What was fed beyond the cut never arrived.
        self.hb_arrivals = [a for a in self.hb_arrivals if a <= g_cut]
        self.ts_probes = {k: a for k, a in self.ts_probes.items() if a <= g_cut}
        self.param_probes = [a for a in self.param_probes if a <= g_cut]
        # What a restore may give: the last complete save, or the one under way.
        in_progress = bool(self.saves) and (g_cut - self.saves[-1][1] < SAVE_GAP_NS or
                                            machine.flash.next_event_ns() is not None)
        complete = self.saves[:-1] if in_progress else self.saves
        if complete and complete[-1][0] > self.saved_at:
            self.saved, self.saved_at = self._values_at(complete[-1][0]), complete[-1][0]
        options = [("the last complete save", dict(self.saved))]
        if in_progress:
            options.append(("the save under way", self._values_at(self.saves[-1][0])))
        image = machine.flash.kept_at_power_off()
        if self.args.inject == "volatile-flash":
            image = None
        new, problems = power_cycled(self.fil, self.elf, self.board, self.args, image)
        self.boots += 1
        self.base = g_cut + POWER_OFF_NS
        if problems:
            raise SoakFailure(f"brown-out at {g_cut / 1e9:.2f} s: the boot: {problems}")
        self._attach(new)
        hb_before = len(self.hb_arrivals)
        behind_before = self.signed["behind"]
        boot_g = self.now()
        # What was fed to the old chip for after the cut was sent all the same: what was sent
        # while the board was off or booting is lost, the rest reaches the new chip (the
        # frames as they were, signatures and all: re-making them would give the autopilot's
        # signing clock a second pass over the same time).
        resend = [s for s in self.recent_sends if s[0] >= boot_g]
        self.recent_sends = []
        self._feed(self.fed_until, sent=resend)
        self._advance(self.now() + 1.0e9)
        first_hb = next((a for a in self.hb_arrivals[hb_before:]), self.now())
        first_frame = next((start for end, start, k in self.deliveries if start >= self.base),
                           self.now())
        result["end"] = max(first_hb, first_frame)
        got = self._read_all("after the brown-out")
        if self.key is not None:
            saved_from = complete[-1][0] if complete else None
            got[KEY] = self._check_still_signed(g_cut, boot_g, saved_from)
        names = sorted(set(options[0][1]) | set(got))
        matched = None
        for label, want in options:
            if all(got.get(n) == want.get(n) for n in names):
                matched = label
                self.saved, self.saved_at = dict(want), self.now()
                break
        if matched is None:
            diffs = [f"{n} {got.get(n)} (saved {options[0][1].get(n)}"
                     + (f", being saved {options[1][1].get(n)}" if len(options) > 1 else "") + ")"
                     for n in names if any(got.get(n) != w.get(n) for _, w in options)]
            self.problems.append(f"brown-out at {g_cut / 1e9:.2f} s ({note}): parameters after "
                                 f"the boot are neither {' nor '.join(l for l, _ in options)}: "
                                 + ", ".join(diffs[:6]))
            self.saved, self.saved_at = dict(got), self.now()
        result["note"] = f"{note}; restored: {matched or 'WRONG'}"
        if self.key is not None and got.get(KEY) is None:
            # The key's own save was cut: the board is back to no key, and so is the soak.
            self.key = None
            self.ap.mav.signing.sign_outgoing = False
            result["note"] += ", the key with it"
        behind = self.signed["behind"] - behind_before
        if behind:
            result["note"] += (f"; {behind} frames signed behind the board's earlier "
                               f"timestamps, the last {(self.behind_until - boot_g) / 1e6:.0f} "
                               "ms after the boot")

    # --- MAVLink 2 signing (--soak-signing) ---------------------------------------------

    def _count_signature(self, g, m):
        """With a key: checks the signature of a frame the board sent (SHA-256 over the key
        and the frame, MAVLink 2's signature), and whether its timestamp is newer than every
        earlier one: a receiver applying the replay rule (the autopilot) drops it otherwise."""
        if self.key is None:
            return True
        status, timestamp = signature_status(self.key, bytes(m.get_msgbuf()),
                                             self.board_timestamp)
        self.signed[status] += 1
        if status == "behind":
            self.behind_until = g
        if status != "sig_ok":
            return False
        self.board_timestamp = timestamp
        return True

    def _signer(self, key, link_id):
        mav = mavlink.MAVLink(None, srcSystem=GCS_SYSID, srcComponent=GCS_COMPID)
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = link_id
        mav.signing.timestamp = SIGNING_EPOCH_TS
        return mav

    def _set_param(self, name, value, mav=None, keep=None):
        return self._pack(self.gcs.param_set_encode(
            FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), value,
            mavlink.MAV_PARAM_TYPE_REAL32), mav, keep)

    def _signed_flood(self, result):
        """With signing (`--soak-signing`): the first time a SETUP_SIGNING (unsigned: the
        board has no key yet; the autopilot gets the key too and signs from then on, as
        ArduPilot does). Then PARAM_SETs signed with the key, unsigned, signed with another
        key and replayed (a signed frame sent again): only the first kind may apply, each
        parameter reads back as the signed ones set it; reading (PARAM_REQUEST_READ) stays
        open. Then the flight lock: with the autopilot armed, a signed PARAM_SET is
        refused, one of TD_LOCK itself is not (TD_LOCK 0 lets the next one through; TD_LOCK
        goes back to 1), and a signed SETUP_SIGNING with another key is refused. Every frame
        the board sends once it has the key must carry a valid signature (`_count_signature`)."""
        rng = self.rng
        g0 = self.now() + 0.02e9
        problems = []
        if self.key is None:
            key = bytes(rng.randrange(256) for _ in range(32))
            setup = self.gcs.setup_signing_encode(FIRMWARE_SYSID, FIRMWARE_COMPID, list(key),
                                                  SIGNING_EPOCH_TS + int(g0 / 1e4))
            self._advance(g0 + 0.05e9, [(g0, self._pack(setup, self.gcs), "setup")])
            self.signer = self._signer(key, 1)
            self.key = key
            self.value_log.append((self.arrivals.pop("setup"), KEY, key))
            self.values[KEY] = key
            ap = self.ap.mav.signing
            ap.secret_key, ap.sign_outgoing, ap.link_id = key, True, 0
            ap.timestamp = SIGNING_EPOCH_TS
            self.setup_at = self.now()
        wrong = self._signer(bytes(32 - i for i in range(32)), 2)
        model = {name: self.values.get(name) for name in FLOOD_SETTABLE}
        extra, kept, t = [], [], self.now()
        counts = {"signed": 0, "unsigned": 0, "wrong key": 0, "replayed": 0}
        for _ in range(rng.randint(60, 120)):
            t += rng.uniform(1e6, 4e6)
            name = rng.choice(FLOOD_SETTABLE)
            value = a_valid_value(rng, name)
            r = rng.random()
            if r < 0.4:
                extra.append((t, self._set_param(name, value, self.signer, kept), None))
                model[name] = valid_value(name, value)
                counts["signed"] += 1
            elif r < 0.65:
                extra.append((t, self._set_param(name, value, self.gcs), None))
                counts["unsigned"] += 1
            elif r < 0.85:
                extra.append((t, self._set_param(name, value, wrong), None))
                counts["wrong key"] += 1
            elif counts["signed"]:
                # A signed frame sent earlier, again, byte for byte (chosen when it is fed:
                # the frames are signed then).
                pick = rng.random()
                extra.append((t, lambda g, pick=pick: kept[int(pick * len(kept))], None))
                counts["replayed"] += 1
        extra.append((t, b"", "signed-end"))
        self._advance(t + 0.3e9, extra)
        result["end"] = self.arrivals.pop("signed-end")
        problems += self._read_back(model, list(FLOOD_SETTABLE), "after the signed flood")
        answer_ns = self.last_read_back_ns
        # The flight lock.
        self.ap.armed = True
        g = self.next_hb + 0.05e9  # the first HEARTBEAT saying armed has arrived
        name = rng.choice(FLOOD_SETTABLE)
        value = a_valid_value(rng, name)
        while valid_value(name, value) == model[name]:
            value = a_valid_value(rng, name)
        other_key = bytes(range(1, 33))
        self._advance(g + 0.1e9, [
            (g, self._set_param(name, value, self.signer), None),
            (g + 5e6, self._pack(self.gcs.setup_signing_encode(
                FIRMWARE_SYSID, FIRMWARE_COMPID, list(other_key), SIGNING_EPOCH_TS + int(g / 1e4)),
                self.signer), None)])
        problems += self._read_back(model, [name], "after a signed PARAM_SET while armed")
        g = self.now()
        unlocked = valid_value(name, a_valid_value(rng, name))
        self._advance(g + 0.1e9, [(g, self._set_param("TD_LOCK", 0.0, self.signer), None),
                                  (g + 5e6, self._set_param(name, unlocked, self.signer), None)])
        model[name] = unlocked
        model["TD_LOCK"] = 0.0
        problems += self._read_back(model, [name, "TD_LOCK"], "armed, after a signed TD_LOCK 0")
        g = self.now()
        self._advance(g + 0.1e9, [(g, self._set_param("TD_LOCK", 1.0, self.signer), None)])
        model["TD_LOCK"] = 1.0
        problems += self._read_back(model, ["TD_LOCK"], "armed, after a signed TD_LOCK 1")
        self.ap.armed = False
        self._advance(self.next_hb + 0.05e9)
        sigs = self.signed
        print(f"  signing: sent {counts}; the board's frames since the key: {sigs}")
        if sigs["unsigned"] or sigs["bad_sig"]:
            problems.append(f"the board sent {sigs['unsigned']} unsigned frames and "
                            f"{sigs['bad_sig']} with a bad signature after SETUP_SIGNING")
        self.problems += [f"signed flood at {g0 / 1e9:.2f} s: {p}" for p in problems]
        result["note"] = ", ".join(f"{v} {k}" for k, v in counts.items()) + \
            ", flight lock (armed)"
        result["answer_ns"] = answer_ns

    def _check_still_signed(self, g_cut, boot_g, saved_from):
        """After a brown-out with the key saved: the board signs every frame, an unsigned
        PARAM_SET is refused; the last signed PARAM_SET before the cut, sent again (a
        replay the board's forgotten streams cannot recognise; the key's saved timestamp
        must), is refused if a save from `saved_from` on held it, and said either way.
        Returns the board's value of KEY as seen: the key when every frame since the boot
        was signed with it, None when none was."""
        since = self._rx_since(boot_g)
        unsigned = sum(1 for _, m in since if not bytes(m.get_msgbuf())[2] & 1)
        if since and unsigned == len(since):
            return None
        if unsigned:
            self.problems.append(f"brown-out at {g_cut / 1e9:.2f} s: {unsigned} of "
                                 f"{len(since)} frames unsigned after the boot")
        self._replay_after_boot(g_cut, saved_from)
        name = FLOOD_SETTABLE[0]
        old = self.values.get(name)
        value = 2.0 if old != 2.0 else 1.0
        g = self.now()
        self._advance(g + 0.1e9, [(g, self._set_param(name, value, self.gcs), "unsigned set")])
        answers = self._answers(name, self.arrivals.pop("unsigned set"))
        if not answers or answers[-1][1] != old:
            self.problems.append(f"brown-out at {g_cut / 1e9:.2f} s: after it an unsigned "
                                 f"PARAM_SET of {name} was not refused "
                                 f"({answers[-1][1] if answers else 'no answer'})")
        return self.key

    def _replay_after_boot(self, g_cut, saved_from):
        """The last signed PARAM_SET sent before the cut, sent again as it was, first thing
        after the boot (its stream is new to the board, whose streams a reboot forgets): a
        refusal says so by STATUSTEXT (the first refusal after a boot is never held back by
        the texts' rate limit)."""
        writes = [w for w in self.signed_writes if w[0] < g_cut and w[2] in FLOOD_SETTABLE]
        if not writes:
            return
        sent_at, frame, name, _ = writes[-1]
        g = self.now()
        self._advance(g + 0.1e9, [(g, lambda _g: frame, "replay")])
        arrival = self.arrivals.pop("replay")
        texts = [m.text for _, m in self._rx_since(arrival) if m.get_type() == "STATUSTEXT"]
        taken = not any("refused" in t for t in texts)
        held = saved_from is not None and sent_at < saved_from
        self.replays.append((g_cut, name, taken, held))
        if taken and held:
            self.problems.append(f"brown-out at {g_cut / 1e9:.2f} s: the signed PARAM_SET of "
                                 f"{name} sent {(g_cut - sent_at) / 1e9:.2f} s before the cut, "
                                 "whose save completed, was taken again when sent again after "
                                 "the boot")

    # --- the end ------------------------------------------------------------------------

    def _final_checks(self):
        problems = self.problems
        if self.bad_targets:
            problems.append(f"{self.bad_targets} LANDING_TARGETs disagree with the truth, first: "
                            + " | ".join(self.first_bad))
        if not self.good_targets:
            problems.append("no LANDING_TARGET agreed with the truth")
        # TIMESYNC probes. In line noise a false start in the garbage can hold a probe that
        # follows it until the false frame's announced length has arrived (the parser cannot
        # tell sooner): those are reported apart, not held to the bound.
        late, lost, rtts, noisy = [], 0, [], []
        for ts1, arrival in self.ts_probes.items():
            if arrival > self.now() - 0.1e9:
                continue
            rtt = self._ts_rtt(ts1, arrival)
            if rtt is None:
                if not self._lost_to_brown_out(arrival):
                    lost += 1
                continue
            if self._in([(g0, g1 + 0.1e9) for g0, g1 in self.noisy], arrival):
                noisy.append(rtt)
                continue
            rtts.append(rtt)
            if rtt > TIMESYNC_LIMIT_NS:
                late.append(f"{arrival / 1e9:.3f} s: {rtt / 1e6:.1f} ms")
        self.timesync_rtts = rtts
        self.timesync_noisy = noisy
        if lost:
            problems.append(f"{lost} TIMESYNC probes not answered")
        if late:
            problems.append(f"{len(late)} TIMESYNC probes answered after "
                            f"{TIMESYNC_LIMIT_NS / 1e6:g} ms: {', '.join(late[:4])}")
        # PARAM_REQUEST_READ probes.
        latencies, lost_p = [], 0
        for arrival in self.param_probes:
            if arrival > self.now() - 0.2e9:
                continue
            answers = self._answers(PROBE_PARAM, arrival)
            if not answers or answers[0][0] - arrival > 0.5e9:
                if not self._lost_to_brown_out(arrival):
                    lost_p += 1
                continue
            latencies.append(answers[0][0] - arrival)
        self.param_latencies = latencies
        if lost_p:
            problems.append(f"{lost_p} PARAM_REQUEST_READ probes not answered")
        slow = [x for x in latencies if x > PARAM_ANSWER_LIMIT_NS]
        if slow:
            problems.append(f"{len(slow)} PARAM_REQUEST_READ probes answered after "
                            f"{PARAM_ANSWER_LIMIT_NS / 1e6:g} ms (worst {max(slow) / 1e6:.1f} ms)")
        # The board's HEARTBEAT, per boot.
        beats = [g for g, m in self.rx if m.get_type() == "HEARTBEAT"]
        gaps = [b - a for a, b in zip(beats, beats[1:]) if not self._cut_between(a, b)]
        self.hb_gap = max(gaps, default=0)
        if self.hb_gap > 1.5e9:
            problems.append(f"the board's HEARTBEAT paused {self.hb_gap / 1e9:.2f} s")
        # The link's dropped events: none once the link runs (2 s after each boot).
        grew = []
        for boot in sorted({b for _, b, _ in self.dropped_events}):
            counts = [(g, c) for g, b, c in self.dropped_events if b == boot]
            settled = [c for g, c in counts if g >= counts[0][0] + 2e9]
            if settled and settled[-1] > settled[0]:
                grew.append(f"boot {boot}: {settled[0]} -> {settled[-1]}")
        self.dropped_summary = max((c for _, _, c in self.dropped_events), default=None)
        if grew:
            problems.append(f"the link dropped events (its channel was full): {', '.join(grew)}")
        # The stack.
        warmup = max(self.start + min(WARMUP_NS, self.seconds * 1e9 / 2),
                     self.first_round_end or 0)
        before = max((m for g, _, m in self.stack_marks if g < warmup), default=0)
        after = max((m for g, _, m in self.stack_marks if g >= warmup), default=0)
        self.stack_before, self.stack_after = before, after
        if after > before + STACK_GROWTH_BOUND:
            problems.append(f"the stack's high-water mark grew after the warm-up: {before} -> "
                            f"{after} bytes (bound {STACK_GROWTH_BOUND})")
        kinds = {r["kind"] for r in self.results}
        missing = [k for k in KINDS if k not in kinds]
        if missing and not self.stopped and not any("(boot" in p for p in problems):
            problems.append(f"disturbances that never ran: {missing}")

    def _cut_between(self, a, b):
        return any(a <= g <= b for g in self.cuts)

    def _lost_to_brown_out(self, arrival):
        """A probe that arrived shortly before a power cut went down with the board."""
        return any(g - 0.1e9 <= arrival <= g for g in self.cuts)

    def _summary(self):
        end = self.now()
        print(f"  soak: {(end - self.start) / 1e9:.1f} s emulated (seed {self.seed}) in "
              f"{self.wall:.0f} s wall, {self.boots} boot(s), {len(self.good_targets)} good "
              f"LANDING_TARGETs, {self.bad_targets} wrong")
        print(f"  {'disturbance':16s} {'count':>5s} {'resume frames':>13s} {'resume ms':>9s} "
              f"{'target gap ms':>13s} {'TIMESYNC ms':>11s} {'PARAM ms':>8s} {'stack':>6s}")
        for kind in list(KINDS) + ["signed-flood"]:
            rs = [r for r in self.results if r["kind"] == kind]
            if not rs:
                continue

            def worst(key, scale=1e6):
                vals = [r[key] for r in rs if r.get(key) is not None]
                return f"{max(vals) / scale:.1f}" if vals else "-"
            frames = [r["resume_frames"] for r in rs if r["resume_frames"] is not None]
            print(f"  {kind:16s} {len(rs):5d} {max(frames) if frames else '-':>13} "
                  f"{worst('resume_ns'):>9s} {worst('gap_ns'):>13s} {worst('timesync_ns'):>11s} "
                  f"{worst('answer_ns'):>8s} {max(r['stack'] for r in rs):6d}")
        if self.timesync_rtts:
            rtts = self.timesync_rtts
            print(f"  TIMESYNC probes: {len(rtts)} answered, {min(rtts) / 1e6:.2f} to "
                  f"{max(rtts) / 1e6:.2f} ms; first third worst "
                  f"{max(rtts[:len(rtts) // 3 or 1]) / 1e6:.2f} ms, last third "
                  f"{max(rtts[-(len(rtts) // 3 or 1):]) / 1e6:.2f} ms")
        if self.timesync_noisy:
            noisy = self.timesync_noisy
            print(f"  TIMESYNC probes during line noise: {len(noisy)} answered, "
                  f"{min(noisy) / 1e6:.2f} to {max(noisy) / 1e6:.2f} ms, "
                  f"{sum(1 for r in noisy if r > TIMESYNC_LIMIT_NS)} after "
                  f"{TIMESYNC_LIMIT_NS / 1e6:g} ms")
        if self.param_latencies:
            lat = self.param_latencies
            print(f"  PARAM_REQUEST_READ probes: {len(lat)} answered, {min(lat) / 1e6:.2f} to "
                  f"{max(lat) / 1e6:.2f} ms")
        print(f"  board HEARTBEAT: longest gap {self.hb_gap / 1e9:.2f} s (outside brown-outs); "
              f"link events dropped: {self.dropped_summary}")
        print(f"  stack high-water: {self.stack_before} bytes before the warm-up's end, "
              f"{self.stack_after} after; new peaks (s: bytes, during): "
              + ", ".join(f"{g / 1e9:.1f}: {m} ({k or 'quiet'})" for g, m, k in self.stack_rises))
        saves = len(self.saves)
        print(f"  flash: {saves} save(s), {self.words_per_save} flash words each")
        if self.replays:
            held = [r for r in self.replays if r[3]]
            lost = [r for r in self.replays if not r[3]]
            print(f"  replays after a brown-out of the last signed PARAM_SET: {len(held)} whose "
                  f"save completed, {sum(r[2] for r in held)} taken; {len(lost)} whose save "
                  f"the cut lost, {sum(r[2] for r in lost)} taken")
        if self.key is not None:
            sigs = self.signed
            print(f"  signing: the board's frames since the key: {sigs['sig_ok']} signed, "
                  f"{sigs['unsigned']} unsigned, {sigs['bad_sig']} with a bad signature, "
                  f"{sigs['behind']} signed behind an earlier timestamp (after brown-outs)")
