"""Puts the peripheral models on the emulated chip's bus: exactly the blocks the firmware's
boot path and tasks use; any other peripheral address is a failure (see bus.py)."""

from .devices import Gpio, Iwdg, RegisterFile, Tim2
from .machine import Machine
from .rcc import Flash, Pwr, Rcc, Syscfg

GPIO_BASE = 0x5802_0000


def build_chip(elf, board, args):
    machine = Machine(elf, spin_bound=args.spin_bound)
    machine.rcc = machine.add_block(Rcc(board.hse_hz))
    machine.pwr = machine.add_block(Pwr())
    machine.flash = machine.add_block(Flash())
    machine.syscfg = machine.add_block(Syscfg())
    if args.inject == "no-pll1rdy":
        machine.rcc.inject_no_pll1rdy()
    for i, letter in enumerate("ABCDEFGHIJK"):
        machine.add_block(Gpio(GPIO_BASE + 0x400 * i, letter))
    machine.add_block(Tim2())
    machine.add_block(Iwdg())
    machine.add_block(RegisterFile(0x5800_0000, "EXTI"))
    machine.add_block(RegisterFile(0x5C00_1000, "DBGMCU", reset={0x00: 0x2003_6450}))
    for base, name in ((0x4802_0000, "DCMI"), (0x4002_0000, "DMA1"), (0x4002_0400, "DMA2"),
                       (0x4002_0800, "DMAMUX1"), (0x4000_5400, "I2C1"),
                       (board.uart_base, board.uart_name)):
        machine.add_block(RegisterFile(base, name))
    return machine
