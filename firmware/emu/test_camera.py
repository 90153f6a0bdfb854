"""Tests of the emulated OV7725's exposure registers (run by scripts/emu_boot.sh):
`python3 -m unittest discover -s firmware/emu -t firmware`."""

import unittest

from emu.camera import Ov7725

GAIN, AECH, AEC, COM8, COM7 = 0x00, 0x08, 0x10, 0x13, 0x12


def write(sensor, register, value, now_ns=0.0):
    sensor.write(bytes([register, value]), now_ns)


class Exposure(unittest.TestCase):
    def test_after_a_reset_the_sensor_s_own_aec_runs(self):
        sensor = Ov7725()
        write(sensor, COM7, 0x80)
        self.assertIsNone(sensor.manual_exposure())

    def test_manual_lines_and_gain_as_the_registers_say(self):
        sensor = Ov7725()
        write(sensor, COM8, 0xCF & ~0x05)
        write(sensor, AECH, 0x01)
        write(sensor, AEC, 0x2C)
        # GAIN 0x34: two doublings (bits 4 and 5) of 1 + 4/16.
        write(sensor, GAIN, 0x34)
        self.assertEqual(sensor.manual_exposure(), (0x12C, 20 * 4))

    def test_a_frame_takes_the_setting_in_force_when_it_starts(self):
        sensor = Ov7725()
        write(sensor, COM8, 0x0A, now_ns=10.0)
        write(sensor, AEC, 30, now_ns=20.0)
        write(sensor, AEC, 15, now_ns=50.0)
        self.assertIsNone(sensor.exposure_at(5.0))
        self.assertEqual(sensor.exposure_at(30.0), (30, 16))
        self.assertEqual(sensor.exposure_at(50.0), (15, 16))

    def test_a_sensor_deaf_to_its_exposure_keeps_its_setting(self):
        sensor = Ov7725(fixed_exposure=True)
        write(sensor, COM8, 0x0A)
        write(sensor, AEC, 30)
        write(sensor, GAIN, 0x10)
        self.assertEqual(sensor.manual_exposure(), (1, 16))


if __name__ == "__main__":
    unittest.main()
