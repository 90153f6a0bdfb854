"""Puts the peripheral models on the emulated chip's bus: exactly the blocks the firmware's
boot path and tasks use; any other peripheral address is a failure (see bus.py)."""

from .camera import DMA1_IRQS, DMA2_IRQS, Dcmi, Dma, Dmamux, I2c, Ov7725
from .devices import Gpio, Iwdg, RegisterFile, Tim2
from .flash import SECTOR_SIZE, Flash
from .machine import Machine
from .rcc import Pwr, Rcc, Syscfg
from .uart import Usart

GPIO_BASE = 0x5802_0000
SENSOR_FPS = 30


def build_chip(elf, board, args, frames=((320, 240, bytes(320 * 240)),)):
    """The chip with `board`'s wiring; the camera streams `frames` (width, height, grey
    bytes), cycled."""
    machine = Machine(elf, spin_bound=args.spin_bound)
    if board.foreign_sector is not None:
        # Another firmware's data (not erased, no parameter slot in it): the parameter store
        # must erase it before it can save there (firmware/src/param_store.rs).
        pattern = b"ROMFS\0" + bytes(range(256))
        sector = (pattern * (SECTOR_SIZE // len(pattern) + 1))[:SECTOR_SIZE]
        machine.uc.mem_write(board.foreign_sector, sector)
    machine.rcc = machine.add_block(Rcc(board.hse_hz))
    machine.pwr = machine.add_block(Pwr())
    machine.flash = machine.add_block(Flash())
    machine.flash.attach(machine)
    machine.syscfg = machine.add_block(Syscfg())
    if args.inject == "no-pll1rdy":
        machine.rcc.inject_no_pll1rdy()
    machine.gpios = [machine.add_block(Gpio(GPIO_BASE + 0x400 * i, letter))
                     for i, letter in enumerate("ABCDEFGHIJK")]
    machine.add_block(Tim2())
    machine.iwdg = machine.add_block(Iwdg())
    machine.add_block(RegisterFile(0x5800_0000, "EXTI"))
    machine.add_block(RegisterFile(0x5C00_1000, "DBGMCU", reset={0x00: 0x2003_6450}))
    dmamux = machine.add_block(Dmamux())
    dmas = [machine.add_block(Dma(0x4002_0000, "DMA1", DMA1_IRQS, dmamux, 0)),
            machine.add_block(Dma(0x4002_0400, "DMA2", DMA2_IRQS, dmamux, 8))]
    machine.sensor = Ov7725(present=args.inject != "no-camera",
                            fixed_exposure=args.inject == "fixed-exposure")
    machine.i2c = machine.add_block(I2c(machine.sensor, dmas))
    machine.dcmi = machine.add_block(Dcmi(list(frames), SENSOR_FPS, dmas, machine.sensor))
    machine.uart = machine.add_block(
        Usart(board.uart_base, board.uart_name, board.uart_irq, board.uart_clock))
    return machine
