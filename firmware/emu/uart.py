"""The flight-controller UART (USART6 on the NUCLEO, USART3 on the OpenMV; RM0433 §48,
FIFO mode as embassy enables it), with the line to an emulated autopilot.

Transmit: every byte written to TDR joins a 16-byte FIFO and leaves one frame time (10 bits at
the baud rate BRR gives from the kernel clock, rcc_pclk2 / rcc_pclk1 by default) after the
previous one; TXE (TXFNF) reads 1 while the FIFO has room, TC once it is empty. Bytes that left
are collected in `sent` with their emulated time.

Receive: `feed(bytes, at_ns)` puts bytes on the line; each arrives one frame time after the
previous one into a 16-byte FIFO (RXNE, read through RDR); a byte arriving at a full FIFO is
lost and sets ORE; one frame time of silence after a byte sets IDLE.

The interrupt is up while RXNE&RXNEIE, IDLE&IDLEIE, TXE&TXEIE, TC&TCIE or ORE&(RXNEIE|EIE);
ICR clears IDLE, TC, ORE and the error flags.
"""

from collections import deque

from .bus import Block

FIFO = 16
PE, FE, NE, ORE, IDLE, RXNE, TC, TXE = (1 << i for i in range(8))
TEACK, REACK = 1 << 21, 1 << 22


class Usart(Block):
    names = {0x00: "CR1", 0x04: "CR2", 0x08: "CR3", 0x0C: "BRR", 0x1C: "ISR", 0x20: "ICR",
             0x24: "RDR", 0x28: "TDR"}

    def __init__(self, base, name, irq, kernel_clock):
        super().__init__(base, name)
        self.irq = irq
        self.kernel_clock = kernel_clock  # name of the RCC clock feeding it
        self.tx = deque()   # completion times of the bytes in the TX FIFO
        self.tx_bytes = deque()
        self.sent = []      # (time ns, byte)
        self.line = deque()  # (arrival ns, byte) still on the wire
        self.rx = deque()
        self.flags = 0
        self.idle_at = None  # when the line, silent since the last byte, counts as idle

    def frame_ns(self):
        brr = self.regs.get(0x0C, 0) or 1
        hz = self.machine.rcc.clocks()[self.kernel_clock]
        return 10 * brr * 1e9 / hz

    def baud(self):
        return self.machine.rcc.clocks()[self.kernel_clock] / (self.regs.get(0x0C, 0) or 1)

    def feed(self, data, at_ns):
        """Puts `data` on the receive line starting at `at_ns`."""
        t = max(at_ns, self.line[-1][0] if self.line else at_ns)
        for byte in data:
            t += self.frame_ns()
            self.line.append((t, byte))

    def read_reg(self, off):
        if off == 0x1C:
            self.advance(self.machine.time_ns)
            return self._isr()
        if off == 0x24:
            self.advance(self.machine.time_ns)
            return self.rx.popleft() if self.rx else 0
        return self.regs.get(off, 0)

    def _isr(self):
        isr = self.flags | TEACK | REACK
        if self.rx:
            isr |= RXNE
        if len(self.tx) < FIFO:
            isr |= TXE
        return isr

    def write_reg(self, off, value):
        if off == 0x20:
            self.flags &= ~(value & (PE | FE | NE | ORE | IDLE | TC))
            return
        if off == 0x28:
            self.advance(self.machine.time_ns)
            if len(self.tx) >= FIFO:
                self.machine.fail(f"{self.name}: TDR written with the TX FIFO full",
                                  self.base + off)
            start = max(self.machine.time_ns, self.tx[-1] if self.tx else 0)
            self.tx.append(start + self.frame_ns())
            self.tx_bytes.append(value & 0xFF)
            self.flags &= ~TC
            return
        self.regs[off] = value

    def advance(self, now_ns):
        while self.tx and self.tx[0] <= now_ns:
            self.sent.append((self.tx.popleft(), self.tx_bytes.popleft()))
            if not self.tx:
                self.flags |= TC
        while True:
            next_byte = self.line[0][0] if self.line else float("inf")
            if self.idle_at is not None and self.idle_at <= now_ns and self.idle_at < next_byte:
                self.flags |= IDLE
                self.idle_at = None
            elif next_byte <= now_ns:
                t, byte = self.line.popleft()
                if len(self.rx) < FIFO:
                    self.rx.append(byte)
                else:
                    self.flags |= ORE
                self.idle_at = t + self.frame_ns()
            else:
                break

    def next_event_ns(self):
        times = [t for t in (self.tx[0] if self.tx else None,
                             self.line[0][0] if self.line else None, self.idle_at)
                 if t is not None]
        return min(times) if times else None

    def irq_lines(self):
        cr1, cr3, isr = self.regs.get(0x00, 0), self.regs.get(0x08, 0), self._isr()
        up = (isr & RXNE and cr1 & 0x20) or (isr & IDLE and cr1 & 0x10) or \
             (isr & TXE and cr1 & 0x80) or (isr & TC and cr1 & 0x40) or \
             (isr & ORE and (cr1 & 0x20 or cr3 & 1))
        return (self.irq,) if up else ()
