"""The STM32H743's memory map (RM0433 chapter 2, "Memory map and register boundary addresses"),
the only memory the emulated firmware may touch. Everything not listed is unmapped: an access
there is a failure (on the chip it is a bus fault).

The peripheral space (0x4000_0000-0x5FFF_FFFF) and the Cortex-M7's system space
(0xE000_0000-0xE00F_FFFF) are not RAM: they are served by the register models (bus.py) through
one MMIO callback each, and an access to a block no model claims is a failure too.
"""

from dataclasses import dataclass

KIB = 1024


@dataclass(frozen=True)
class Region:
    """One block of memory: name, base, size; `clock_bit`: the RCC_AHB2ENR bit that must be set
    before it may be accessed (SRAM1-3 are unclocked after reset), or None."""

    name: str
    base: int
    size: int
    clock_bit: int = None

    @property
    def end(self):
        return self.base + self.size

    def contains(self, addr):
        return self.base <= addr < self.end


ITCM = Region("ITCM", 0x0000_0000, 64 * KIB)
FLASH = Region("FLASH", 0x0800_0000, 2048 * KIB)
DTCM = Region("DTCM", 0x2000_0000, 128 * KIB)
AXISRAM = Region("AXI SRAM", 0x2400_0000, 512 * KIB)
SRAM1 = Region("SRAM1", 0x3000_0000, 128 * KIB, clock_bit=29)
SRAM2 = Region("SRAM2", 0x3002_0000, 128 * KIB, clock_bit=30)
SRAM3 = Region("SRAM3", 0x3004_0000, 32 * KIB, clock_bit=31)
SRAM4 = Region("SRAM4", 0x3800_0000, 64 * KIB)
BACKUP_SRAM = Region("backup SRAM", 0x3880_0000, 4 * KIB)

MEMORIES = (ITCM, FLASH, DTCM, AXISRAM, SRAM1, SRAM2, SRAM3, SRAM4, BACKUP_SRAM)

PERIPHERALS = Region("peripherals", 0x4000_0000, 0x2000_0000)
SYSTEM = Region("system", 0xE000_0000, 0x0010_0000)

# Erased flash reads as 0xFF (the parameter sector in particular).
FLASH_ERASED = 0xFF


def region_of(addr):
    """The memory region holding `addr`, or None."""
    for region in MEMORIES:
        if region.contains(addr):
            return region
    return None
