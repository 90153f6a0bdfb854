"""A host tool run against the emulated board over a TCP port on 127.0.0.1: the emulator
listens, starts the tool with the port, and between slices of emulated time moves bytes both
ways through two callbacks (the RTT channel of view.py, the UART of lens.py), while the
emulated autopilot's messages are fed a little ahead of the emulation as FIL feeds them.

The tool runs on the wall clock and the board on emulated time, which runs slower: the tool
only ever waits longer than it would on a board, never less.
"""

import socket
import subprocess

# Emulated time between two looks at the board's side: a debugger polling every 10 ms.
POLL_NS = 10e6
# How far ahead of the emulation the autopilot's messages are put on the line (a tool's bytes
# wait behind them).
FEED_AHEAD_NS = 0.05e9


class Run:
    """What a bridged run gave: the tool's exit status and output, and the emulated times at
    its start, at its connection (None if it never connected) and at its end."""

    def __init__(self, returncode, stdout, stderr, start_ns, attached_ns, end_ns, timed_out):
        self.returncode = returncode
        self.stdout = stdout
        self.stderr = stderr
        self.start_ns = start_ns
        self.attached_ns = attached_ns
        self.end_ns = end_ns
        self.timed_out = timed_out

    def last_line(self, text):
        lines = text.strip().splitlines()
        return lines[-1] if lines else ""


def run_tool(machine, autopilot, command, to_board, from_board, max_ns):
    """Runs `command(port)` (the tool's argv) against the board until it exits or `max_ns` of
    emulated time pass: bytes from the tool go to `to_board(data)`, and `from_board()`'s bytes
    (polled every POLL_NS) to the tool. Returns a Run."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    listener.setblocking(False)
    tool = subprocess.Popen(command(listener.getsockname()[1]), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    conn, pending, attached = None, b"", None
    start = machine.time_ns
    machine.stop_at_first_idle = False
    machine.finished = None
    fed_until = start + 0.05e9
    try:
        while machine.time_ns < start + max_ns and tool.poll() is None:
            if fed_until < machine.time_ns + FEED_AHEAD_NS:
                autopilot.feed(machine, fed_until, fed_until + FEED_AHEAD_NS)
                fed_until += FEED_AHEAD_NS
            machine.run(machine.time_ns + POLL_NS, machine.pc())
            if machine.failure or machine.finished:
                break
            if conn is None:
                try:
                    conn, _ = listener.accept()
                    conn.setblocking(False)
                    attached = machine.time_ns
                except BlockingIOError:
                    continue
            try:
                data = conn.recv(4096)
                if data:
                    to_board(data)
            except BlockingIOError:
                pass
            pending += from_board()
            while pending:
                try:
                    sent = conn.send(pending)
                except BlockingIOError:
                    break
                pending = pending[sent:]
        end = machine.time_ns
        # What was fed is consumed before the next stage feeds its own.
        if not (machine.failure or machine.finished):
            machine.run(fed_until, machine.pc())
    finally:
        if conn is not None:
            conn.close()
        listener.close()
    timed_out = False
    try:
        out, err = tool.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        tool.kill()
        out, err = tool.communicate()
        timed_out = True
    return Run(tool.returncode, out.decode(errors="replace"), err.decode(errors="replace"),
               start, attached, end, timed_out)
