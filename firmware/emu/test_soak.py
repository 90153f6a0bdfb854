"""Tests of the soak's own helpers (soak.py): its mirror of the parameter validation, the
resume count and the signature check, against pymavlink's signing. Run by
scripts/emu_boot.sh: `python3 -m unittest discover -s firmware/emu -t firmware`."""

import math
import random
import unittest

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from emu.soak import (FLOOD_SETTABLE, PARAM_RANGES, a_valid_value, invalid_value,
                      resume_frames, signature_status, valid_value)

PERIOD = 1e9 / 30


class Validation(unittest.TestCase):
    def test_ranges_integers_and_unset_zero(self):
        self.assertEqual(valid_value("TD_RATE_HZ", 30.0), 30.0)
        self.assertIsNone(valid_value("TD_RATE_HZ", 0.0))
        self.assertIsNone(valid_value("TD_RATE_HZ", 30.5))
        self.assertIsNone(valid_value("TD_BAUD", math.nan))
        self.assertIsNone(valid_value("TD_CAM_POS_X", math.inf))
        self.assertEqual(valid_value("TD_TAG_SIZE", 0.0), 0.0)
        self.assertIsNone(valid_value("TD_TAG_SIZE", 0.01))
        self.assertEqual(valid_value("TD_CAM_POS_X", -0.0), 0.0)
        # The f32 a PARAM_SET carries, not the double.
        self.assertNotEqual(valid_value("TD_PAD_YAW", 0.1), 0.1)
        self.assertAlmostEqual(valid_value("TD_PAD_YAW", 0.1), 0.1, places=6)

    def test_the_flood_values_are_what_they_claim(self):
        rng = random.Random(3)
        for _ in range(2000):
            name = rng.choice(sorted(PARAM_RANGES))
            self.assertIsNone(valid_value(name, invalid_value(rng, name)))
            settable = rng.choice(FLOOD_SETTABLE)
            self.assertIsNotNone(valid_value(settable, a_valid_value(rng, settable)))


class Resume(unittest.TestCase):
    frames = [((k + 0.9) * PERIOD, k * PERIOD, "pad") for k in range(10)]

    def test_counts_the_frames_from_the_end_to_the_first_good_target(self):
        end = 3.5 * PERIOD
        # Frames end at 3.9, 4.9, ... periods; the target 5 ms after the second of them.
        target = 4.9 * PERIOD + 5e6
        self.assertEqual(resume_frames(self.frames, [target], end)[0], 2)

    def test_a_target_of_a_frame_before_the_end_does_not_count(self):
        end = 3.5 * PERIOD
        early = 3.6 * PERIOD  # sent after the end, but before a frame after it ended
        self.assertEqual(resume_frames(self.frames, [early, 3.9 * PERIOD + 1e6], end)[0], 1)

    def test_frames_without_the_pad_do_not_end_it_and_no_target_is_none(self):
        frames = [(e, s, "blank" if k < 5 else "pad") for k, (e, s, _) in
                  enumerate(self.frames)]
        self.assertEqual(resume_frames(frames, [5.9 * PERIOD + 1e6], 5 * PERIOD)[0], 1)
        self.assertEqual(resume_frames(frames, [], 0.0), (None, None))

    def test_frames_the_camera_did_not_deliver_count(self):
        # The sensor is back at 2.5 periods; the firmware takes its first frame at 6.9.
        frames = [f for f in self.frames if not 2 <= f[1] / PERIOD < 6]
        self.assertEqual(resume_frames(frames, [6.9 * PERIOD + 1e6], 2.5 * PERIOD)[0], 5)


class Signatures(unittest.TestCase):
    def signed_frame(self, key, timestamp):
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.timestamp = timestamp
        return mav.heartbeat_encode(18, 8, 0, 0, 4).pack(mav)

    def test_pymavlinks_signature_checks_and_the_replay_rule(self):
        key = bytes(range(32))
        frame = self.signed_frame(key, 1000)
        self.assertEqual(signature_status(key, frame, 999), ("sig_ok", 1000))
        self.assertEqual(signature_status(key, frame, 1000), ("behind", 1000))
        self.assertEqual(signature_status(bytes(32), frame, 0)[0], "bad_sig")
        broken = bytearray(frame)
        broken[12] ^= 1
        self.assertEqual(signature_status(key, bytes(broken), 0)[0], "bad_sig")
        unsigned = mavlink.MAVLink(None).heartbeat_encode(18, 8, 0, 0, 4).pack(
            mavlink.MAVLink(None))
        self.assertEqual(signature_status(key, unsigned, 0), ("unsigned", None))


if __name__ == "__main__":
    unittest.main()
