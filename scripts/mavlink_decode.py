"""Decodes a file of MAVLink frames with pymavlink, strictly: the reference decoder of the
companion tests (core/tests/companion_*.rs, through core/tests/autopilot_sim/decoded.rs) and
of the host tool's `touchdown companion --serial` test over a pty (companion_serial.rs).

Usage: python3 scripts/mavlink_decode.py FRAMES.bin

Prints one JSON object per message (the message's fields plus `_type`, `_seq`, `_src`,
`_mlen` = payload length on the wire, `_version`), then a summary line
{"_summary": true, "messages": N, "leftover": bytes}. pymavlink's parser runs with
robust_parsing off, so a bad CRC, a wrong CRC_EXTRA or any framing error raises: that is
reported as {"_error": "..."} with exit status 2. Exit status 3 with "skipping: pymavlink not
installed" on stdout when pymavlink is missing.
"""

import json
import math
import sys

try:
    from pymavlink.dialects.v20 import common as mavlink2
except ImportError:
    print("skipping: pymavlink not installed")
    sys.exit(3)


def clean(value):
    """JSON has no NaN/inf: map them to None; recurse into lists; bytes to text."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    if isinstance(value, bytes):
        return value.decode("ascii", "replace")
    return value


def main():
    data = open(sys.argv[1], "rb").read()
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = False
    count = 0
    try:
        msgs = mav.parse_buffer(data) or []
    except Exception as exc:  # pymavlink raises MAVError (and struct errors) on bad data
        print(json.dumps({"_error": str(exc)}))
        sys.exit(2)
    for m in msgs:
        if m.get_type() == "BAD_DATA":
            print(json.dumps({"_error": "BAD_DATA: %s" % getattr(m, "reason", "")}))
            sys.exit(2)
        d = {k: clean(v) for k, v in m.to_dict().items()}
        header = m.get_header()
        d["_type"] = m.get_type()
        d["_seq"] = header.seq
        d["_src"] = [header.srcSystem, header.srcComponent]
        d["_mlen"] = header.mlen
        d["_version"] = 2 if m.get_msgbuf()[0:1] == b"\xfd" else 1
        print(json.dumps(d))
        count += 1
    print(json.dumps({"_summary": True, "messages": count, "leftover": mav.buf_len()}))


main()
