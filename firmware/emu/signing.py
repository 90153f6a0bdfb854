"""Stage 3 (`--signing`), MAVLink signing and the key through a power cycle: after
firmware-in-the-loop (fil.py) a ground station (255/190) gives the firmware a signing key
with an unsigned SETUP_SIGNING (the first key is taken unsigned), then sends unsigned,
signed, older-signed and replayed PARAM_SETs; the chip is powered off and on with its flash,
and the ground station writes again, unsigned and signed.

Why: the key must reach the parameter flash through the same debounced save as a parameter,
come back at boot, and every frame the firmware sends afterwards must carry a signature the
reference implementation (pymavlink, given the key, with no allowance for unsigned frames)
accepts; a write that is not signed with it must change nothing, before and after the power
cycle.

Checked: STATUSTEXT "touchdown: signing on"; the unsigned PARAM_SET answered with the old
value and refused; the signed ones applied (TD_TAG_SIZE to half the pad, so the
LANDING_TARGETs after it are at half the truth's distance, as in power_cycle.py; TD_RATE_HZ
15 then 20); TD_RATE_HZ 10 signed with an older timestamp, and the TD_RATE_HZ 15 frame sent
again, refused (20 holds); every frame the firmware sent from the key on signed and
accepted by pymavlink; flash programmed. After the power cycle: the boot test passes;
the frames are signed from the first; an unsigned PARAM_SET of TD_RATE_HZ is refused, as is
the TD_RATE_HZ 20 frame sent once more (the board forgot its senders at the power cycle, not
the timestamp saved past its last write), a new signed one applied; the targets at half
distance.
"""

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from . import memmap
from .autopilot import FIRMWARE_COMPID, FIRMWARE_SYSID
from .boot import report_stack
from .fil import messages_since, timed_messages
from .power_cycle import (SAVE_WAIT_NS, half_pad_size, half_size_target_problems,
                          power_cycled)

# The ground station's key (any 32 bytes) and its initial timestamp (2026, 10 us units since
# 2015-01-01).
KEY = bytes(range(0x40, 0x60))
INITIAL_TIMESTAMP = 11 * 365 * 24 * 3600 * 100_000
GCS = (255, 190)
AFTER_BOOT_NS = 1.5e9


class Ground:
    """A ground station's frames, signed with KEY at chosen timestamps, or unsigned."""

    def __init__(self):
        self.mav = mavlink.MAVLink(None, srcSystem=GCS[0], srcComponent=GCS[1])

    def frame(self, msg, timestamp=None):
        self.mav.signing.secret_key = KEY if timestamp is not None else None
        self.mav.signing.sign_outgoing = timestamp is not None
        if timestamp is not None:
            self.mav.signing.timestamp = timestamp
        return msg.pack(self.mav)

    def setup_signing(self):
        return self.frame(self.mav.setup_signing_encode(
            FIRMWARE_SYSID, FIRMWARE_COMPID, KEY, INITIAL_TIMESTAMP))

    def param_set(self, name, value, timestamp=None):
        return self.frame(self.mav.param_set_encode(
            FIRMWARE_SYSID, FIRMWARE_COMPID, name.encode(), value,
            mavlink.MAV_PARAM_TYPE_REAL32), timestamp)


def frames_from(machine, since_ns):
    """The bytes of every whole frame the firmware started sending from `since_ns` on."""
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    sent = machine.uart.sent
    out = bytearray()
    for i, (_, b) in enumerate(sent):
        m = mav.parse_char(bytes([b]))
        if m is None or m.get_type() == "BAD_DATA":
            continue
        buf = m.get_msgbuf()
        start = i - len(buf) + 1
        if start >= 0 and sent[start][0] >= since_ns:
            out += buf
    return bytes(out)


def signature_problems(data, when):
    """pymavlink's verdict on `data` with KEY and no unsigned allowance: a problem for a frame
    it refuses."""
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = False
    mav.signing.secret_key = KEY
    try:
        msgs = mav.parse_buffer(data) or []
    except Exception as exc:  # pymavlink raises MAVError on an unsigned or bad frame
        return [f"{when}: pymavlink refused a frame: {exc}"]
    print(f"  signing {when}: {len(msgs)} frames, {mav.signing.goodsig_count} good signatures, "
          f"{mav.signing.badsig_count} bad")
    if not msgs:
        return [f"{when}: no frames"]
    if mav.signing.goodsig_count != len(msgs) or mav.signing.badsig_count:
        return [f"{when}: {mav.signing.goodsig_count} good signatures of {len(msgs)} frames"]
    return []


def value_after(messages, name, asked_by, want):
    values = [m for m in messages if m.get_type() == "PARAM_VALUE"
              and m.param_id.rstrip("\0") == name]
    if not values:
        return [f"no PARAM_VALUE {name} answered the {asked_by}"]
    got = values[0].param_value
    print(f"  PARAM_VALUE {name} = {got:g} (answering the {asked_by})")
    if abs(got - want) > 1e-6:
        return [f"PARAM_VALUE {name} {got:g} answered the {asked_by}, expected {want:g}"]
    return []


class Signing:
    """The stage: `run` takes the machine FIL ran on and returns the problems found."""

    def __init__(self, fil, elf, board, args):
        self.fil, self.elf, self.board, self.args = fil, elf, board, args
        self.autopilot = fil.autopilot
        self.half = half_pad_size()
        self.ground = Ground()

    def run(self, machine):
        problems = self._key_and_writes(machine)
        if problems:
            return problems
        return self._after_power_cycle(machine)

    def _key_and_writes(self, machine):
        g = self.ground
        t0 = machine.time_ns
        ts = INITIAL_TIMESTAMP
        rate_15 = g.param_set("TD_RATE_HZ", 15.0, ts + 200)
        self.rate_20 = g.param_set("TD_RATE_HZ", 20.0, ts + 300)
        writes = [
            (0.10, "SETUP_SIGNING", g.setup_signing()),
            (0.30, "unsigned TD_TAG_SIZE", g.param_set("TD_TAG_SIZE", self.half)),
            (0.50, "signed TD_TAG_SIZE", g.param_set("TD_TAG_SIZE", self.half, ts + 100)),
            (0.70, "signed TD_RATE_HZ 15", rate_15),
            (0.90, "signed TD_RATE_HZ 20", self.rate_20),
            (1.10, "older TD_RATE_HZ 10", g.param_set("TD_RATE_HZ", 10.0, ts + 250)),
            (1.30, "replayed TD_RATE_HZ 15", rate_15),
        ]
        at = {label: t0 + s * 1e9 for s, label, _ in writes}
        end = at["replayed TD_RATE_HZ 15"] + SAVE_WAIT_NS
        self.autopilot.feed(machine, t0 + 0.05e9, end,
                            [(at[label], data) for _, label, data in writes])
        written = len(machine.flash.programmed)
        machine.run(end, machine.pc())
        problems = [machine.failure] if machine.failure else []
        if machine.finished:
            problems.append(f"stopped early: {machine.finished}")
        timed = timed_messages(machine)
        texts = [m.text for m in messages_since(timed, at["SETUP_SIGNING"])
                 if m.get_type() == "STATUSTEXT"]
        for text in sorted(set(texts)):
            print(f"  STATUSTEXT: {text}")
        if "touchdown: signing on" not in texts:
            problems.append("no STATUSTEXT 'touchdown: signing on' after SETUP_SIGNING")
        if not any("TD_TAG_SIZE refused: not signed" in t for t in texts):
            problems.append("no STATUSTEXT refusing the unsigned PARAM_SET")

        def since(label):
            return messages_since(timed, at[label])

        problems += value_after(since("unsigned TD_TAG_SIZE"), "TD_TAG_SIZE",
                                "unsigned PARAM_SET", 0.0)
        problems += value_after(since("signed TD_TAG_SIZE"), "TD_TAG_SIZE",
                                "signed PARAM_SET", self.half)
        for label, want in [("signed TD_RATE_HZ 15", 15.0), ("signed TD_RATE_HZ 20", 20.0),
                            ("older TD_RATE_HZ 10", 20.0), ("replayed TD_RATE_HZ 15", 20.0)]:
            problems += value_after(since(label), "TD_RATE_HZ", label, want)
        problems += half_size_target_problems(self.autopilot, messages_since(timed, at["signed TD_TAG_SIZE"] + 0.5e9),
                                        "after the signed TD_TAG_SIZE")
        # Frames started 50 ms after the SETUP_SIGNING reached the line: the key is in force.
        problems += signature_problems(frames_from(machine, at["SETUP_SIGNING"] + 0.05e9),
                                       "after SETUP_SIGNING")
        if len(machine.flash.programmed) == written:
            problems.append("no flash word programmed after the key and the writes (the save)")
        return problems

    def _after_power_cycle(self, old):
        image = bytes(old.uc.mem_read(memmap.FLASH.base, memmap.FLASH.size))
        print("  power cycle: a new chip with the old flash")
        machine, problems = power_cycled(self.fil, self.elf, self.board, self.args, image)
        if problems:
            return [f"after the power cycle: {p}" for p in problems]
        g = self.ground
        start = machine.time_ns
        unsigned_at, replay_at, signed_at = start + 0.3e9, start + 0.45e9, start + 0.6e9
        end = start + AFTER_BOOT_NS
        self.autopilot.feed(machine, start + 0.05e9, end, [
            (unsigned_at, g.param_set("TD_RATE_HZ", 5.0)),
            # The last write before the power cycle, sent again: the board forgot its senders
            # but not the timestamp saved past that write.
            (replay_at, self.rate_20),
            (signed_at, g.param_set("TD_RATE_HZ", 25.0, INITIAL_TIMESTAMP + 400)),
        ])
        machine.run(end, machine.pc())
        if machine.failure:
            return [f"after the power cycle: {machine.failure}"]
        if machine.finished:
            problems.append(f"after the power cycle: stopped early: {machine.finished}")
        timed = timed_messages(machine)
        problems += value_after(messages_since(timed, unsigned_at), "TD_RATE_HZ",
                                "unsigned PARAM_SET after the power cycle", 20.0)
        problems += value_after(messages_since(timed, replay_at), "TD_RATE_HZ",
                                "replayed PARAM_SET after the power cycle", 20.0)
        problems += value_after(messages_since(timed, signed_at), "TD_RATE_HZ",
                                "signed PARAM_SET after the power cycle", 25.0)
        problems += half_size_target_problems(self.autopilot, messages_since(timed, start + 0.3e9),
                                        "after the power cycle")
        problems += signature_problems(frames_from(machine, start), "after the power cycle")
        problems += [f"after the power cycle: {p}" for p in report_stack(machine)]
        return problems
