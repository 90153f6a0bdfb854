"""Stage `--view TOUCHDOWN`, the frame stream to a host viewer end to end: after
firmware-in-the-loop (fil.py) the emulator serves the firmware's RTT channel 1 on a TCP port
on 127.0.0.1, both ways, as a debugger's RTT server does (OpenOCD's `rtt server start PORT 1`),
draining the up channel and filling the down channel between slices of emulated time
(bridge.py), and runs `touchdown view tcp:... --record DIR --frames N` against it.

Why: the stream crosses the firmware's vision task (which fills the record), its view task
(which reads the viewer's requests from the down channel and trickles the record into the up
channel) and the host's reader; only all of them together show that what the board saw
reaches the host whole and means what the board meant.

Checked: the viewer ends by itself with N frames recorded; the recording is the board's
frame size and camera; `touchdown detect --method board` (the board's detector) on each
recorded frame, given the recording's camera and the families the board reported, finds
exactly the markers the board reported
(same family and id, corners within CORNER_TOLERANCE_PX); the board's pad fix puts the camera
where the frame's truth has it; and the flight path did not notice: the LANDING_TARGETs
came at the rate they came at before the viewer attached (at least TARGET_RATE_KEPT of it).
"""

import csv
import json
import os
import shutil
import struct
import subprocess
import tempfile

from .bridge import run_tool
from .fil import timed_messages

# Frames the viewer records.
FRAMES = 3
# Longest emulated time the stage may take (three QVGA records, 77 KB each through an 8 KB
# channel, take about 0.6 s).
MAX_EMULATED_NS = 4e9
# Same detections: corners this close (pixels), ids and families equal.
CORNER_TOLERANCE_PX = 0.01
# The board's fix: the camera within this fraction of the range from where the truth has it.
DISTANCE_TOLERANCE = 0.03
# The LANDING_TARGET rate while the viewer is attached, at least this fraction of the rate
# before it.
TARGET_RATE_KEPT = 0.9

# rtt-target's control block: a 16-byte id, the up and down channel counts, then 24-byte
# channels (name, buffer, size, write offset, read offset, flags).
RTT_ID = b"SEGGER RTT"
CHANNEL_LEN = 24


class RttChannels:
    """The firmware's RTT control block, read and written in emulated memory."""

    def __init__(self, machine, address):
        self.uc = machine.uc
        header = bytes(self.uc.mem_read(address, 24))
        if not header.startswith(RTT_ID):
            raise ValueError(f"no RTT control block at {address:#010x}")
        self.up_count, self.down_count = struct.unpack_from("<II", header, 16)
        self.address = address

    def _channel(self, index, down):
        base = self.address + 24 + CHANNEL_LEN * (index + (self.up_count if down else 0))
        name, buf, size, write, read, flags = struct.unpack(
            "<6I", bytes(self.uc.mem_read(base, CHANNEL_LEN)))
        return base, buf, size, write, read

    def drain_up(self, index):
        """Everything the firmware wrote into up channel `index` since the last drain."""
        base, buf, size, write, read = self._channel(index, down=False)
        if buf == 0 or size == 0 or write == read:
            return b""
        if write > read:
            data = bytes(self.uc.mem_read(buf + read, write - read))
        else:
            data = bytes(self.uc.mem_read(buf + read, size - read))
            data += bytes(self.uc.mem_read(buf, write))
        self.uc.mem_write(base + 16, struct.pack("<I", write))
        return data

    def fill_down(self, index, data):
        """Writes as much of `data` into down channel `index` as it has room for; returns the
        count written."""
        base, buf, size, write, read = self._channel(index, down=True)
        if buf == 0 or size == 0:
            return 0
        room = (read - write - 1) % size
        data = data[:room]
        for byte in data:
            self.uc.mem_write(buf + write, bytes([byte]))
            write = (write + 1) % size
        self.uc.mem_write(base + 12, struct.pack("<I", write))
        return len(data)


def target_rate(machine, since_ns, until_ns):
    """LANDING_TARGETs per emulated second between the two times."""
    n = sum(1 for t, m in timed_messages(machine)
            if since_ns <= t < until_ns and m.get_type() == "LANDING_TARGET")
    return n / max((until_ns - since_ns) / 1e9, 1e-9)


class View:
    """The stage (see the module docs)."""

    def __init__(self, fil, elf, board, args):
        self.fil = fil
        self.elf = elf
        self.touchdown = args.view
        # `--inject view-unasked`: the requests are dropped, so the board, which streams only
        # when asked, must send nothing and the stage must fail.
        self.deaf = args.inject == "view-unasked"

    def run(self, machine):
        print(f"  view: touchdown view --record, {FRAMES} frames, over RTT channel 1")
        problems = []
        rtt = RttChannels(machine, self.elf.sym("_SEGGER_RTT"))
        before_start = max(machine.time_ns - 0.5e9, 0.0)
        rate_before = target_rate(machine, before_start, machine.time_ns)
        work = tempfile.mkdtemp(prefix="touchdown-emu-view-")
        try:
            problems += self._stream(machine, rtt, work, rate_before)
            if not problems:
                problems += self._check_recording(os.path.join(work, "rec"))
        finally:
            if os.environ.get("EMU_VIEW_KEEP"):
                print(f"  view: kept {work} (EMU_VIEW_KEEP)")
            else:
                shutil.rmtree(work, ignore_errors=True)
        return problems

    def _stream(self, machine, rtt, work, rate_before):
        up_bytes = 0

        def to_board(data):
            if not self.deaf:
                rtt.fill_down(1, data)

        def from_board():
            nonlocal up_bytes
            data = rtt.drain_up(1)
            up_bytes += len(data)
            return data

        def command(port):
            return [self.touchdown, "view", f"tcp:127.0.0.1:{port}", "--record",
                    os.path.join(work, "rec"), "--frames", str(FRAMES), "--image",
                    os.path.join(work, "view.png"), "--timeout", "60"]

        run = run_tool(machine, self.fil.autopilot, command, to_board, from_board,
                       MAX_EMULATED_NS)
        problems = []
        if run.timed_out:
            problems.append(f"touchdown view did not end within {MAX_EMULATED_NS / 1e9:g} s "
                            "emulated")
        if machine.failure:
            problems.append(machine.failure)
        if machine.finished:
            problems.append(f"view stage stopped early: {machine.finished}")
        if run.stdout.strip():
            print(f"  view: the viewer's last line: {run.last_line(run.stdout)}")
        summary = run.last_line(run.stderr)
        print(f"  view: {up_bytes} bytes from RTT channel 1 in "
              f"{(run.end_ns - run.start_ns) / 1e6:.0f} ms emulated; viewer: "
              f"{summary or '(nothing)'}")
        if run.returncode != 0:
            problems.append(f"touchdown view exited {run.returncode}: {summary}")
        if run.attached_ns is not None and run.end_ns - run.attached_ns > 0.5e9:
            rate = target_rate(machine, run.attached_ns, run.end_ns)
            print(f"  view: LANDING_TARGETs {rate_before:.1f}/s before the viewer, {rate:.1f}/s "
                  "while it streamed")
            if rate < TARGET_RATE_KEPT * rate_before:
                problems.append(f"LANDING_TARGETs slowed to {rate:.1f}/s while streaming (from "
                                f"{rate_before:.1f}/s)")
        return problems

    def _check_recording(self, rec):
        problems = []
        with open(os.path.join(rec, "frames.csv")) as f:
            frames = list(csv.DictReader(f))
        if len(frames) != FRAMES:
            return [f"the recording holds {len(frames)} frames, expected {FRAMES}"]
        camera = {}
        with open(os.path.join(rec, "camera.toml")) as f:
            for line in f:
                if "=" in line and not line.lstrip().startswith("#"):
                    key, value = (s.strip() for s in line.split("=", 1))
                    camera[key] = value
        want_size = (self.fil.frame[0], self.fil.frame[1])
        if (int(camera.get("width", 0)), int(camera.get("height", 0))) != want_size:
            problems.append(f"recorded camera {camera.get('width')}x{camera.get('height')}, the "
                            f"board's frames are {want_size[0]}x{want_size[1]}")
        with open(os.path.join(rec, "board_markers.csv")) as f:
            board = list(csv.DictReader(f))
        with open(os.path.join(rec, "board.csv")) as f:
            board_frames = list(csv.DictReader(f))
        families = sorted({row["family"] for row in board})
        if not board:
            return problems + ["the board reported no marker in the streamed frames"]
        command = [self.touchdown, "detect", "--method", "board", "--json", "--camera",
                   os.path.join(rec, "camera.toml")]
        for family in families:
            command += ["--family", family]
        command += [os.path.join(rec, "frames", f"{int(row['index']):06d}.pgm") for row in frames]
        result = subprocess.run(command, capture_output=True, text=True, timeout=120)
        if result.returncode != 0:
            return problems + [f"touchdown detect failed: {result.stderr.strip()}"]
        replayed = [json.loads(line) for line in result.stdout.splitlines() if line.strip()]
        worst = 0.0
        for index, detected in enumerate(replayed):
            mine = {(row["family"], int(row["id"])):
                    [float(row[f"c{i}{a}"]) for i in range(4) for a in "xy"]
                    for row in board if int(row["index"]) == index}
            theirs = {(d["family"], d["id"]): [v for c in d["corners"] for v in c]
                      for d in detected["detections"]}
            if set(mine) != set(theirs):
                problems.append(f"frame {index}: the board reported {sorted(mine)}, the replay "
                                f"found {sorted(theirs)}")
                continue
            for key, corners in mine.items():
                worst = max([worst] + [abs(a - b) for a, b in zip(corners, theirs[key])])
        print(f"  view: {len(board)} board markers in {FRAMES} frames, the replay's corners within "
              f"{worst:.4f} px of them")
        if worst > CORNER_TOLERANCE_PX:
            problems.append(f"replayed corners {worst:.4f} px from the board's (tolerance "
                            f"{CORNER_TOLERANCE_PX} px)")
        truth = [self.fil.truth[f"cam_{a}"] for a in "xyz"]
        distance = sum(v * v for v in truth) ** 0.5
        for row in board_frames:
            if not row["fix_z"]:
                problems.append(f"frame {row['index']}: the board had no pad fix")
                continue
            fix = [float(row[f"fix_{a}"]) for a in "xyz"]
            miss = sum((a - b) ** 2 for a, b in zip(fix, truth)) ** 0.5
            if miss > DISTANCE_TOLERANCE * distance:
                problems.append(f"frame {row['index']}: the board's fix puts the camera at "
                                f"{fix}, {miss:.2f} m from the truth {truth}")
        return problems
