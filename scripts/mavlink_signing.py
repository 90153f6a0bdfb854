"""MAVLink 2 signing by pymavlink, the reference the board's signing is tested against
(core/tests/companion_signing.rs, the emulated firmware's soak).

Usage:
  python3 scripts/mavlink_signing.py sign KEYHEX|- < MESSAGES.jsonl > FRAMES.hex
  python3 scripts/mavlink_signing.py verify KEYHEX FRAMES.bin

`sign`: each input line is a JSON object {"type": "PARAM_SET", "fields": {...}, "src": [sys,
comp], "timestamp": T, "link_id": L}; the output line is that message's frame in hex, signed
by pymavlink with the key at timestamp T (or unsigned when the key is `-` or the line has
"unsigned": true). `verify`: decodes the board's frames with the key set and no unsigned
callback, so that pymavlink raises on any frame whose signature it does not accept; prints one
JSON line {"messages": N, "good": G, "bad": B, "types": {...}} (exit 2 on a refused frame,
3 with "skipping: pymavlink not installed" when pymavlink is missing).
"""

import json
import sys

try:
    from pymavlink.dialects.v20 import common as mavlink2
except ImportError:
    print("skipping: pymavlink not installed")
    sys.exit(3)


def link(key):
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = False
    if key is not None:
        mav.signing.secret_key = key
    return mav


def sign(key):
    for line in sys.stdin:
        if not line.strip():
            continue
        spec = json.loads(line)
        mav = link(None if spec.get("unsigned") else key)
        mav.srcSystem, mav.srcComponent = spec.get("src", [255, 190])
        mav.seq = spec.get("seq", 0)
        if mav.signing.secret_key is not None:
            mav.signing.sign_outgoing = True
            mav.signing.timestamp = spec["timestamp"]
            mav.signing.link_id = spec.get("link_id", 0)
        cls = getattr(mavlink2, "MAVLink_%s_message" % spec["type"].lower())
        fields = dict(spec.get("fields", {}))
        for name, value in fields.items():
            if isinstance(value, str) and name in ("param_id",):
                fields[name] = value.encode()
            if isinstance(value, list) and name == "secret_key":
                fields[name] = bytes(value)
        msg = cls(**fields)
        print(msg.pack(mav).hex())


def verify(key, path):
    mav = link(key)
    data = open(path, "rb").read()
    types = {}
    try:
        msgs = mav.parse_buffer(data) or []
    except Exception as exc:  # pymavlink raises MAVError on a refused signature
        print(json.dumps({"_error": str(exc)}))
        sys.exit(2)
    for m in msgs:
        if m.get_type() == "BAD_DATA":
            print(json.dumps({"_error": "BAD_DATA: %s" % getattr(m, "reason", "")}))
            sys.exit(2)
        types[m.get_type()] = types.get(m.get_type(), 0) + 1
    print(json.dumps({
        "messages": len(msgs),
        "good": mav.signing.goodsig_count,
        "bad": mav.signing.badsig_count,
        "leftover": mav.buf_len(),
        "types": types,
    }))


def main():
    if len(sys.argv) < 3 or sys.argv[1] not in ("sign", "verify"):
        print(__doc__)
        sys.exit(1)
    key = None if sys.argv[2] == "-" else bytes.fromhex(sys.argv[2])
    if sys.argv[1] == "sign":
        sign(key)
    else:
        verify(key, sys.argv[3])


if __name__ == "__main__":
    main()
