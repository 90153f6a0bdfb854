"""Tests of the emulated flash interface's program and erase operations (run by
scripts/emu_boot.sh): `python3 -m unittest discover -s firmware/emu -t firmware`."""

import unittest

from unicorn import UC_ARCH_ARM, UC_MODE_THUMB, UC_PROT_EXEC, UC_PROT_READ, Uc

from emu import memmap
from emu.flash import (ERASE_NS, FLASH_IRQ, KEYS, PROGRAM_NS, SECTOR_SIZE, SR_BSY, SR_EOP, SR_QW,
                       SR_WBNE, Flash)

CR2, SR2, KEYR2, CCR2 = 0x10C, 0x110, 0x104, 0x114
PG, SER, START, EOPIE = 1 << 1, 1 << 2, 1 << 7, 1 << 16
PSIZE_32 = 2 << 4
BANK2 = 0x0810_0000


class FakeMachine:
    """What the flash model uses of the machine: the memory, the time, the failures."""

    def __init__(self):
        self.uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB)
        self.uc.mem_map(memmap.FLASH.base, memmap.FLASH.size, UC_PROT_READ | UC_PROT_EXEC)
        self.uc.mem_write(memmap.FLASH.base, b"\xff" * memmap.FLASH.size)
        self.time_ns = 0.0
        self.failures = []

    def fail(self, message, addr=None):
        self.failures.append(message)


def flash_on_machine():
    machine = FakeMachine()
    flash = Flash()
    flash.machine = machine
    flash.attach(machine)
    return flash, machine


def unlock(flash):
    for key in KEYS:
        flash.write_reg(KEYR2, key)


def store(flash, machine, addr, value):
    """A 32-bit store by the CPU: the model's hook, then the memory write unicorn performs."""
    flash._on_memory_write(machine.uc, 0, addr, 4, value, None)
    machine.uc.mem_write(addr, value.to_bytes(4, "little"))


def program(flash, machine, word, values):
    for k, value in enumerate(values):
        store(flash, machine, word + 4 * k, value)


def finish(flash, machine):
    machine.time_ns = flash.next_event_ns()
    flash.advance(machine.time_ns)


class Keys(unittest.TestCase):
    def test_the_two_keys_unlock_and_cr_lock_locks_again(self):
        flash, machine = flash_on_machine()
        self.assertTrue(flash.read_reg(CR2) & 1)
        unlock(flash)
        self.assertFalse(flash.read_reg(CR2) & 1)
        flash.write_reg(CR2, 1)
        self.assertTrue(flash.read_reg(CR2) & 1)
        self.assertEqual(machine.failures, [])

    def test_a_wrong_key_is_a_failure(self):
        flash, machine = flash_on_machine()
        flash.write_reg(KEYR2, KEYS[1])
        self.assertEqual(len(machine.failures), 1)

    def test_an_erase_asked_while_locked_is_a_failure(self):
        flash, machine = flash_on_machine()
        flash.write_reg(CR2, SER | (7 << 8) | START)
        self.assertEqual(len(machine.failures), 1)
        self.assertIsNone(flash.next_event_ns())


class Erase(unittest.TestCase):
    def test_a_sector_erase_takes_its_time_then_reads_erased_and_interrupts(self):
        flash, machine = flash_on_machine()
        sector = BANK2 + 7 * SECTOR_SIZE
        machine.uc.mem_write(sector, b"ROMFS" * 100)
        unlock(flash)
        flash.write_reg(CR2, SER | (7 << 8) | EOPIE)
        flash.write_reg(CR2, SER | (7 << 8) | EOPIE | START)
        self.assertEqual(flash.read_reg(SR2) & (SR_BSY | SR_QW), SR_BSY | SR_QW)
        self.assertEqual(flash.next_event_ns(), ERASE_NS)
        self.assertEqual(flash.irq_lines(), ())
        finish(flash, machine)
        self.assertEqual(bytes(machine.uc.mem_read(sector, SECTOR_SIZE)), b"\xff" * SECTOR_SIZE)
        self.assertEqual(flash.read_reg(SR2) & (SR_BSY | SR_QW | SR_EOP), SR_EOP)
        self.assertEqual(flash.irq_lines(), (FLASH_IRQ,))
        self.assertEqual(flash.erased, [(ERASE_NS, 1, 7)])
        flash.write_reg(CCR2, SR_EOP)
        self.assertEqual(flash.irq_lines(), ())
        self.assertEqual(machine.failures, [])


class Program(unittest.TestCase):
    def setUp(self):
        self.flash, self.machine = flash_on_machine()
        unlock(self.flash)
        self.flash.write_reg(CR2, PG | PSIZE_32 | EOPIE)
        self.word = BANK2 + 6 * SECTOR_SIZE + 0x40

    def test_eight_words_program_one_flash_word(self):
        flash, machine = self.flash, self.machine
        program(flash, machine, self.word, range(1, 8))
        self.assertEqual(flash.read_reg(SR2) & (SR_WBNE | SR_QW), SR_WBNE)
        store(flash, machine, self.word + 28, 8)
        self.assertEqual(flash.read_reg(SR2) & (SR_WBNE | SR_QW), SR_QW)
        self.assertEqual(flash.next_event_ns(), PROGRAM_NS)
        finish(flash, machine)
        data = bytes(machine.uc.mem_read(self.word, 32))
        self.assertEqual(data, b"".join(v.to_bytes(4, "little") for v in range(1, 9)))
        self.assertEqual(flash.programmed, [(PROGRAM_NS, self.word)])
        self.assertEqual(flash.irq_lines(), (FLASH_IRQ,))
        self.assertEqual(machine.failures, [])

    def test_a_flash_word_is_programmed_once_but_may_be_zeroed(self):
        flash, machine = self.flash, self.machine
        program(flash, machine, self.word, range(1, 9))
        finish(flash, machine)
        program(flash, machine, self.word, [0] * 8)
        finish(flash, machine)
        self.assertEqual(machine.failures, [])
        program(flash, machine, self.word, range(1, 9))
        self.assertEqual(len(machine.failures), 1)

    def test_a_second_flash_word_before_the_first_is_complete_is_a_failure(self):
        flash, machine = self.flash, self.machine
        store(flash, machine, self.word, 1)
        store(flash, machine, self.word + 32, 2)
        self.assertEqual(len(machine.failures), 1)

    def test_clearing_pg_with_a_half_written_flash_word_is_a_failure(self):
        flash, machine = self.flash, self.machine
        store(flash, machine, self.word, 1)
        flash.write_reg(CR2, 0)
        self.assertEqual(len(machine.failures), 1)


class PowerCut(unittest.TestCase):
    """`kept_at_power_off`: what a brown-out (soak.py) leaves in flash."""

    def setUp(self):
        self.flash, self.machine = flash_on_machine()
        unlock(self.flash)
        self.flash.write_reg(CR2, PG | PSIZE_32 | EOPIE)
        self.word = BANK2 + 6 * SECTOR_SIZE + 0x40

    def kept(self, word):
        offset = word - memmap.FLASH.base
        return self.flash.kept_at_power_off()[offset:offset + 32]

    def test_a_programmed_word_is_kept(self):
        program(self.flash, self.machine, self.word, range(1, 9))
        finish(self.flash, self.machine)
        self.assertEqual(self.kept(self.word),
                         b"".join(v.to_bytes(4, "little") for v in range(1, 9)))

    def test_a_word_still_in_the_write_buffer_is_lost(self):
        program(self.flash, self.machine, self.word, range(1, 5))
        self.assertEqual(self.kept(self.word), b"\xff" * 32)

    def test_a_word_cut_while_it_programs_is_lost(self):
        program(self.flash, self.machine, self.word, range(1, 9))
        self.assertEqual(self.flash.read_reg(SR2) & SR_QW, SR_QW)
        self.assertEqual(self.kept(self.word), b"\xff" * 32)

    def test_an_erase_cut_short_leaves_the_sector(self):
        sector = BANK2 + 7 * SECTOR_SIZE
        self.machine.uc.mem_write(sector, b"slot" * 8)
        self.flash.write_reg(CR2, SER | (7 << 8))
        self.flash.write_reg(CR2, SER | (7 << 8) | START)
        self.assertEqual(self.kept(sector), b"slot" * 8)


if __name__ == "__main__":
    unittest.main()
