"""Tests of the ELF reading the emulator depends on (run by scripts/emu_boot.sh):
`python3 -m unittest discover -s firmware/emu -t firmware`."""

import unittest

from emu.elfimage import demangle, thumb_hint_sites

SEV = 0xBF40
BASE = 0x0800_0000


def code(*halfwords):
    return b"".join(h.to_bytes(2, "little") for h in halfwords)


class HintSites(unittest.TestCase):
    def test_a_hint_that_starts_an_instruction_is_sure(self):
        # movs r0, #3; sev; bx lr
        data = code(0x2003, SEV, 0x4770)
        self.assertEqual(thumb_hint_sites(BASE, data, [(BASE, "t")], SEV), [(BASE + 2, True)])

    def test_the_second_half_of_a_32_bit_instruction_is_not_a_hint(self):
        # movs r0, #13; b.w +0x1E80 (f001 bf40, its second half has SEV's bits); sev
        data = code(0x200D, 0xF001, SEV, SEV)
        self.assertEqual(thumb_hint_sites(BASE, data, [(BASE, "t")], SEV), [(BASE + 6, True)])

    def test_the_decode_restarts_at_each_code_mapping_symbol(self):
        # A 32-bit prefix in data must not shift the decode of the code after it.
        data = code(0x4770, 0xF001, SEV, SEV)
        mapping = [(BASE, "t"), (BASE + 2, "d"), (BASE + 6, "t")]
        self.assertEqual(thumb_hint_sites(BASE, data, mapping, SEV), [(BASE + 6, True)])

    def test_data_is_not_a_hint(self):
        data = code(0x4770, SEV, SEV)
        mapping = [(BASE, "t"), (BASE + 2, "d")]
        self.assertEqual(thumb_hint_sites(BASE, data, mapping, SEV), [])

    def test_without_mapping_symbols_nothing_is_sure(self):
        data = code(0x200D, 0xF001, SEV)
        self.assertEqual(thumb_hint_sites(BASE, data, [], SEV), [(BASE + 4, False)])


class Demangle(unittest.TestCase):
    def test_legacy_rust_names(self):
        self.assertEqual(
            demangle("_ZN4core3ptr13drop_in_place17h0123456789abcdefE"),
            "core::ptr::drop_in_place")
        self.assertEqual(demangle("main"), "main")


if __name__ == "__main__":
    unittest.main()
