"""Models of the peripherals the firmware drives besides the clocks: GPIO, the TIM2 time base,
the independent watchdog, and plain register files for the blocks whose registers are only
configured (EXTI, DBGMCU). The camera path (I2C1, DCMI, DMA) and the UART are in camera.py and
uart.py.
"""

from .bus import Block
from .rcc import LSI_HZ


class RegisterFile(Block):
    """A block that only needs to read back what was written (configuration registers)."""

    def __init__(self, base, name, size=0x400, reset=None):
        super().__init__(base, name)
        self.size = size
        if reset:
            self.regs.update(reset)


class Gpio(Block):
    """One GPIO port (RM0433 §11.4): BSRR sets/resets ODR bits, IDR reads ODR (outputs loop
    back; inputs read low). Pin changes are recorded as (time ns, pin, level)."""

    names = {0x00: "MODER", 0x10: "IDR", 0x14: "ODR", 0x18: "BSRR"}

    def __init__(self, base, letter):
        super().__init__(base, f"GPIO{letter}")
        self.letter = letter
        # Reset: PA13/14/15 and PB3/4 are debug pins; everything else analog (0xFFFFFFFF).
        self.regs[0x00] = {"A": 0xABFF_FFFF, "B": 0xFFFF_FEBF}.get(letter, 0xFFFF_FFFF)
        self.changes = []

    def read_reg(self, off):
        if off == 0x10:
            return self.regs.get(0x14, 0)
        if off == 0x18:
            return 0
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        if off == 0x18:
            odr = self.regs.get(0x14, 0)
            odr = (odr | (value & 0xFFFF)) & ~(value >> 16) if value else odr
            self._set_odr(odr)
        elif off == 0x14:
            self._set_odr(value & 0xFFFF)
        else:
            self.regs[off] = value

    def _set_odr(self, odr):
        old = self.regs.get(0x14, 0)
        for pin in range(16):
            if (old ^ odr) >> pin & 1:
                self.changes.append((self.machine.time_ns, f"P{self.letter}{pin}", odr >> pin & 1))
        self.regs[0x14] = odr


class Tim2(Block):
    """TIM2 as embassy's time driver uses it (RM0433 §38): the counter runs at the APB1 timer
    clock / (PSC + 1) while CR1.CEN is set, wraps at ARR (update event, SR.UIF); SR.CCxIF rise
    when the counter passes CCRx; DIER enables the interrupt (IRQ 28). EGR.UG reloads the
    prescaler and clears the counter. SR bits are cleared by writing 0 (rc_w0)."""

    name = "TIM2"
    IRQ = 28
    names = {0x00: "CR1", 0x0C: "DIER", 0x10: "SR", 0x14: "EGR", 0x24: "CNT", 0x28: "PSC",
             0x2C: "ARR", 0x34: "CCR1", 0x38: "CCR2", 0x3C: "CCR3", 0x40: "CCR4"}
    reset = {0x2C: 0xFFFF_FFFF}

    def __init__(self, base=0x4000_0000):
        super().__init__(base)
        self.origin_ticks = 0.0   # tick count (at the tick rate) when CNT was 0
        self.seen_ticks = 0       # ticks up to which events have been flagged
        self.running = False

    def tick_hz(self):
        return self.machine.rcc.clocks()["tim_apb1"] / (self.regs.get(0x28, 0) + 1)

    def _ticks(self, now_ns=None):
        """Absolute ticks since the counter's origin at emulated time `now_ns`."""
        now = self.machine.time_ns if now_ns is None else now_ns
        return int(now * self.tick_hz() / 1e9 - self.origin_ticks)

    def _period(self):
        return (self.regs[0x2C] & 0xFFFF_FFFF) + 1

    def counter(self):
        return self._ticks() % self._period() if self.running else self.regs.get(0x24, 0)

    def read_reg(self, off):
        if off == 0x24:
            self.advance(self.machine.time_ns)
            return self.counter()
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        if off == 0x00:
            was = self.running
            self.running = bool(value & 1)
            if self.running and not was:
                self._set_counter(self.regs.get(0x24, 0))
            elif was and not self.running:
                self.regs[0x24] = self.counter()
        elif off == 0x10:
            self.regs[0x10] = self.regs.get(0x10, 0) & value
            return
        elif off == 0x14:
            if value & 1:
                self._set_counter(0)
                if not self.regs.get(0x00, 0) & (1 << 2):  # URS=0: UG sets UIF
                    self.regs[0x10] = self.regs.get(0x10, 0) | 1
            return
        elif off == 0x24:
            self._set_counter(value)
        self.regs[off] = value

    def _set_counter(self, value):
        self.regs[0x24] = value
        now_ticks = self.machine.time_ns * self.tick_hz() / 1e9
        self.origin_ticks = now_ticks - value
        self.seen_ticks = int(now_ticks - self.origin_ticks)

    def advance(self, now_ns):
        if not self.running:
            return
        now = self._ticks(now_ns)
        if now <= self.seen_ticks:
            return
        period = self._period()
        flags = 0
        if now // period > self.seen_ticks // period:
            flags |= 1
        for ch in range(4):
            ccr = self.regs.get(0x34 + 4 * ch, 0)
            if self._passes(self.seen_ticks, now, ccr, period):
                flags |= 2 << ch
        self.regs[0x10] = self.regs.get(0x10, 0) | flags
        self.seen_ticks = now

    @staticmethod
    def _passes(start, end, value, period):
        """Whether the counter equals `value` at some tick in (start, end]."""
        first = start + 1 + ((value - (start + 1)) % period)
        return first <= end

    def irq_lines(self):
        return (self.IRQ,) if self.regs.get(0x10, 0) & self.regs.get(0x0C, 0) & 0x1F else ()

    def next_event_ns(self):
        if not self.running:
            return None
        dier = self.regs.get(0x0C, 0)
        period = self._period()
        targets = []
        if dier & 1:
            targets.append(period)
        for ch in range(4):
            if dier & (2 << ch):
                targets.append(self.regs.get(0x34 + 4 * ch, 0) % period)
        if not targets:
            return None
        start = self.seen_ticks
        ticks = min(start + 1 + ((t - (start + 1)) % period) for t in targets)
        return (ticks + self.origin_ticks + 0.5) * 1e9 / self.tick_hz()


class Iwdg(Block):
    """IWDG1 (RM0433 §45): KR 0xCCCC starts it, 0xAAAA reloads, 0x5555 unlocks PR/RLR; the
    down-counter runs at LSI (32 kHz) / (4 << PR) from RLR. Reaching 0 resets the chip, which
    in the emulation is a failure (the firmware stopped feeding it)."""

    name = "IWDG1"
    names = {0x00: "KR", 0x04: "PR", 0x08: "RLR", 0x0C: "SR"}
    reset = {0x08: 0xFFF}

    def __init__(self, base=0x5800_4800):
        super().__init__(base)
        self.started = False
        self.reloaded_ns = 0.0
        self.feeds = 0

    def timeout_ns(self):
        prescaler = 4 << (self.regs.get(0x04, 0) & 7)
        return (self.regs.get(0x08, 0xFFF) + 1) * prescaler * 1e9 / LSI_HZ

    def read_reg(self, off):
        if off == 0x0C:
            return 0  # PVU/RVU/WVU: updates take effect at once
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        if off == 0x00:
            key = value & 0xFFFF
            if key == 0xCCCC:
                self.started = True
                self.reloaded_ns = self.machine.time_ns
            elif key == 0xAAAA:
                self.reloaded_ns = self.machine.time_ns
                self.feeds += 1
            return
        self.regs[off] = value

    def advance(self, now_ns):
        if self.started and now_ns - self.reloaded_ns > self.timeout_ns():
            self.machine.fail(
                f"IWDG reset: not fed for {(now_ns - self.reloaded_ns) / 1e6:.1f} ms "
                f"(timeout {self.timeout_ns() / 1e6:.1f} ms)", self.base)

    def next_event_ns(self):
        return self.reloaded_ns + self.timeout_ns() + 1 if self.started else None
