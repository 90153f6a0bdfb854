"""The two boards as the emulator sees them: which UART the link uses, the HSE, what the clock
tree must come out as (see `firmware/src/clocks.rs` and `firmware/src/board/`), and what their
flash holds when they arrive."""

from dataclasses import dataclass


@dataclass(frozen=True)
class Board:
    name: str
    hse_hz: int
    bypass: bool
    uart_base: int
    uart_irq: int
    uart_name: str
    uart_clock: str  # the RCC clock that feeds the UART at reset (D2CCIP2R = 0)
    led: str         # the heartbeat LED's pin
    # A flash sector that holds another firmware's data when the board arrives (the OpenMV
    # Cam's ROMFS in the last sector of bank 2, which our parameter store uses), or None.
    foreign_sector: int = None

    def expected_clocks(self, cpu_mhz):
        """The tree clocks.rs asks for: a 4 MHz PLL1 reference, VCO = 2 x CPU, VOS1 at 400 MHz,
        VOS0 at 480 MHz."""
        return {
            "bypass": self.bypass,
            "divm": self.hse_hz // 4_000_000,
            "divn": cpu_mhz * 2 // 4,
            "vos": 0 if cpu_mhz > 400 else 1,
            "cpu_hz": cpu_mhz * 1_000_000,
        }


BOARDS = {
    "nucleo": Board("NUCLEO-H743ZI2", 8_000_000, True, 0x4001_1400, 71, "USART6", "pclk2", "PB0"),
    "openmv": Board("OpenMV Cam H7", 12_000_000, False, 0x4000_4800, 39, "USART3", "pclk1", "PC1",
                    foreign_sector=0x081E_0000),
}
