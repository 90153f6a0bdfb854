"""The camera path: DMA1/DMA2 streams with DMAMUX1, I2C1 with an OV7725 on it (the SCCB bus),
and the DCMI delivering frames.

DMA (RM0433 §15, §17): a stream moves data when its peripheral asks. Here the peripheral
models ask directly: a stream is found by its peripheral address (PAR = the peripheral's data
register) among the enabled streams, its DMAMUX1 channel must carry that peripheral's request
(RM0433 Table 121: I2C1 RX 33, TX 34, DCMI 75; a wrong one would hang the chip), and
`Stream.transfer` moves the items, counts NDTR down and, at zero, sets TCIF and clears EN
(normal mode). Flags live in LISR/HISR and are cleared through LIFCR/HIFCR; a stream's
interrupt line is up while a flag and its enable are both set.

I2C1 (RM0433 §47, master mode only): writing CR2.START starts a transfer to SADD; the address
phase and each byte take 9 SCL periods (100 kHz, as the firmware configures). If nothing
answers at that address, NACKF and STOPF (the master sends STOP itself). Otherwise the bytes
go to / come from the device through the DMA stream (TXDMAEN / RXDMAEN), and at the end TCR
(RELOAD), STOPF (AUTOEND) or TC; CR2.STOP sends STOP (STOPF). ICR clears the flags.

The OV7725 (`Ov7725`) answers at 7-bit address 0x21: a one-byte write sets its register
pointer, a two-byte write sets a register, a read returns the pointed register; PID/VER
0x77/0x21, MIDH/MIDL 0x7F/0xA2; COM7 bit 7 resets the registers. Its exposure follows the
registers as the datasheet lays them out: with AEC and AGC off (COM8 bits 0 and 2), the
exposure in line periods is AECH:AEC and the gain GAIN (bits 7:4 each a doubling, bits 3:0
sixteenths on top of one). A frame is exposed with the setting in force when it starts: a
setting the firmware writes while it processes frame n (frame n + 1 already exposing) first
reaches frame n + 2, the latency the firmware's exposure loop is built for.

The frame file is light, not a fixed picture: the DCMI delivers it scaled by the sensor's
exposure x gain against a reference, clipped at 255 (`Dcmi.brightness`). The reference is
half the firmware's first manual setting (`REFERENCE_OF_FIRST_SETTING`): the firmware's own
exposure loop starts on frames twice too bright, their paper clipped, and what it writes
decides what it sees next.

DCMI (RM0433 §34): with CR.ENABLE and CR.CAPTURE set, the next frame from the sensor (frames
start every 1/fps) is delivered when it ends: the frame's bytes (grey, i.e. the Y that
BSM/OEBS select from YUYV; cropped by CWSTRT/CWSIZE when CR.CROP is set) go through the DMA
stream reading DCMI_DR, 4 pixels per 32-bit word; RIS.FRAME rises (and CAPTURE clears in
snapshot mode). A frame larger than the DMA transfer sets RIS.OVR instead.
"""

from .bus import Block

DMA1_IRQS = (11, 12, 13, 14, 15, 16, 17, 47)
DMA2_IRQS = (56, 57, 58, 59, 60, 68, 69, 70)
FLAG_SHIFT = (0, 6, 16, 22)
TCIF, HTIF, TEIF = 1 << 5, 1 << 4, 1 << 3
CR_EN, CR_TCIE, CR_HTIE, CR_TEIE = 1, 1 << 4, 1 << 3, 1 << 2

# The frame file is what the sensor delivers at this fraction of the firmware's first manual
# exposure x gain (see the module docs).
REFERENCE_OF_FIRST_SETTING = 0.5

I2C1_BASE = 0x4000_5400
DCMI_BASE = 0x4802_0000
REQUESTS = {I2C1_BASE + 0x24: 33, I2C1_BASE + 0x28: 34, DCMI_BASE + 0x28: 75}


class Dma(Block):
    """One DMA controller (8 streams)."""

    names = {0x00: "LISR", 0x04: "HISR", 0x08: "LIFCR", 0x0C: "HIFCR"}

    def __init__(self, base, name, irqs, dmamux, first_channel):
        super().__init__(base, name)
        self.irqs = irqs
        self.dmamux = dmamux
        self.first_channel = first_channel
        self.flags = [0] * 8
        self.items_at_start = [0] * 8  # NDTR when the stream was enabled

    def read_reg(self, off):
        if off in (0x00, 0x04):
            first = 4 * (off // 4)
            return sum(self.flags[first + i] << FLAG_SHIFT[i] for i in range(4))
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        if off in (0x08, 0x0C):
            first = 4 * ((off - 8) // 4)
            for i in range(4):
                self.flags[first + i] &= ~(value >> FLAG_SHIFT[i]) & 0x3F
            return
        stream, reg = divmod(off - 0x10, 0x18)
        if off >= 0x10 and reg == 0 and stream < 8 and value & CR_EN and \
                not self.regs.get(off, 0) & CR_EN:
            if self.flags[stream] & (TCIF | HTIF | TEIF):
                self.machine.fail(f"{self.name} stream {stream} enabled with its flags not "
                                  f"cleared ({self.flags[stream]:#x})", self.base + off)
            self.items_at_start[stream] = self.reg(stream, 0x04) & 0xFFFF
        self.regs[off] = value

    def reg(self, stream, reg):
        return self.regs.get(0x10 + 0x18 * stream + reg, 0)

    def set_reg(self, stream, reg, value):
        self.regs[0x10 + 0x18 * stream + reg] = value

    def find(self, par):
        """The enabled stream whose peripheral address is `par`, or None."""
        for stream in range(8):
            if self.reg(stream, 0) & CR_EN and self.reg(stream, 0x08) == par:
                request = self.dmamux.request(self.first_channel + stream)
                if request != REQUESTS.get(par, request):
                    self.machine.fail(f"{self.name} stream {stream} serves {par:#x} with "
                                      f"DMAMUX request {request}, expected {REQUESTS[par]}", par)
                return stream
        return None

    def transfer(self, stream, data=None, count=None):
        """Moves items of one stream: `data` (bytes) into memory (peripheral-to-memory), or
        `count` items out of memory (returned as bytes). Stops at NDTR = 0."""
        cr = self.reg(stream, 0)
        size = 1 << ((cr >> 13) & 3)
        if (cr >> 11) & 3 != (cr >> 13) & 3:
            self.machine.fail(f"{self.name} stream {stream}: PSIZE != MSIZE (FIFO packing) is "
                              "not modelled", self.base + 0x10 + 0x18 * stream)
            return b""
        ndtr = self.reg(stream, 0x04) & 0xFFFF
        start = self.items_at_start[stream]
        addr = self.reg(stream, 0x0C) + (start - ndtr) * size * (cr >> 10 & 1)
        items = min(ndtr, len(data) // size if data is not None else count)
        if addr < 0x2400_0000:
            self.machine.fail(f"{self.name} stream {stream} addresses {addr:#x}: DMA1/DMA2 cannot "
                              "reach ITCM/DTCM (RM0433 bus matrix)", addr)
            return b""
        if not self.machine.mapped(addr, items * size):
            self.machine.fail(f"{self.name} stream {stream}: {items * size} bytes at {addr:#x} are "
                              "not in (clocked) RAM", addr)
            return b""
        uc = self.machine.uc
        if data is not None:
            uc.mem_write(addr, bytes(data[:items * size]))
            out = None
        else:
            out = bytes(uc.mem_read(addr, items * size))
        left = ndtr - items
        self.set_reg(stream, 0x04, left)
        if left * 2 <= start:
            self.flags[stream] |= HTIF
        if left == 0:
            self.flags[stream] |= TCIF
            self.set_reg(stream, 0, cr & ~CR_EN)
        return out

    def irq_lines(self):
        lines = []
        for stream in range(8):
            cr = self.reg(stream, 0)
            enables = (TCIF if cr & CR_TCIE else 0) | (HTIF if cr & CR_HTIE else 0) | \
                      (TEIF if cr & CR_TEIE else 0)
            if self.flags[stream] & enables:
                lines.append(self.irqs[stream])
        return lines


class Dmamux(Block):
    """DMAMUX1: channel n's C(n)CR selects its request (DMAREQ_ID, bits 7:0)."""

    def __init__(self, base=0x4002_0800):
        super().__init__(base, "DMAMUX1")

    def request(self, channel):
        return self.regs.get(4 * channel, 0) & 0xFF


class Ov7725:
    """The sensor's SCCB registers (see the module docs)."""

    ADDRESS = 0x21
    IDS = {0x0A: 0x77, 0x0B: 0x21, 0x1C: 0x7F, 0x1D: 0xA2}
    COM7 = 0x12

    GAIN, AECH, AEC, COM8 = 0x00, 0x08, 0x10, 0x13
    COM8_AUTO_BITS = 0x05  # AGC (bit 2) and AEC (bit 0)

    def __init__(self, present=True, fixed_exposure=False):
        self.present = present  # False: nothing answers (every transfer is NACKed)
        # True: exposure and gain writes are ignored (fault injection: a loop that cannot act)
        self.fixed_exposure = fixed_exposure
        self.regs = {}
        self.pointer = 0
        self.writes = 0
        self.resets = 0
        # (time_ns, (lines, gain in sixteenths) or None) each time the exposure changed.
        self.exposures = []

    def write(self, data, now_ns=0.0):
        if len(data) >= 1:
            self.pointer = data[0]
        if len(data) >= 2:
            self.writes += 1
            if self.pointer == self.COM7 and data[1] & 0x80:
                self.regs = {}
                self.resets += 1
            elif self.fixed_exposure and self.pointer in (self.AECH, self.AEC, self.GAIN):
                pass
            elif self.pointer not in self.IDS:
                self.regs[self.pointer] = data[1]
            setting = self.manual_exposure()
            if not self.exposures or self.exposures[-1][1] != setting:
                self.exposures.append((now_ns, setting))

    def manual_exposure(self):
        """(lines, gain in sixteenths) in force, or None while the sensor's own AEC/AGC
        runs (after a reset COM8 reads as its default, 0xCF: both on)."""
        if self.regs.get(self.COM8, 0xCF) & self.COM8_AUTO_BITS:
            return None
        lines = (self.regs.get(self.AECH, 0) << 8) | self.regs.get(self.AEC, 0)
        gain = self.regs.get(self.GAIN, 0)
        sixteenths = (16 + (gain & 0x0F)) << bin(gain >> 4).count("1")
        return max(lines, 1), sixteenths

    def exposure_at(self, t_ns):
        """The setting in force at `t_ns` (see `manual_exposure`)."""
        setting = None
        for when, value in self.exposures:
            if when > t_ns:
                break
            setting = value
        return setting

    def read(self, n):
        value = self.IDS.get(self.pointer, self.regs.get(self.pointer, 0))
        return bytes([value] * n)


class I2c(Block):
    """I2C1 in master mode with one device on the bus (see the module docs)."""

    name = "I2C1"
    IRQ_EV, IRQ_ER = 31, 32
    SCL_HZ = 100_000
    names = {0x00: "CR1", 0x04: "CR2", 0x10: "TIMINGR", 0x18: "ISR", 0x1C: "ICR",
             0x24: "RXDR", 0x28: "TXDR"}
    TXE, TXIS, RXNE, NACKF, STOPF, TC, TCR, BUSY = 1, 2, 4, 16, 32, 64, 128, 1 << 15

    def __init__(self, device, dmas):
        super().__init__(I2C1_BASE)
        self.device = device
        self.dmas = dmas
        self.isr = self.TXE
        self.done_at = None
        self.transactions = []

    def read_reg(self, off):
        if off == 0x18:
            self.advance(self.machine.time_ns)
            return self.isr
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        if off == 0x1C:
            self.isr &= ~(value & 0x3F38)
            return
        if off == 0x04:
            if value & (1 << 14):
                self._stop()
                value &= ~(1 << 14)
            if value & (1 << 13):
                self._start(value)
        if off == 0x00 and not value & 1:
            self.isr = self.TXE
            self.done_at = None
        self.regs[off] = value

    def _start(self, cr2):
        self.isr &= ~(self.TC | self.TCR)
        self.isr |= self.BUSY
        nbytes = (cr2 >> 16) & 0xFF
        self.done_at = self.machine.time_ns + (1 + nbytes) * 9 * 1e9 / self.SCL_HZ

    def _stop(self):
        self.isr = (self.isr & ~(self.BUSY | self.TC)) | self.STOPF

    def _dma(self, par):
        for dma in self.dmas:
            stream = dma.find(par)
            if stream is not None:
                return dma, stream
        return None, None

    def advance(self, now_ns):
        if self.done_at is None or now_ns < self.done_at:
            return
        self.done_at = None
        cr1, cr2 = self.regs.get(0x00, 0), self.regs.get(0x04, 0)
        self.regs[0x04] = cr2 & ~(1 << 13)
        address = (cr2 >> 1) & 0x7F
        nbytes = (cr2 >> 16) & 0xFF
        reading = bool(cr2 >> 10 & 1)
        if address != self.device.ADDRESS or not self.device.present:
            self.isr = (self.isr | self.NACKF | self.STOPF) & ~self.BUSY
            self.transactions.append((address, "nack", b""))
            return
        if reading:
            data = self.device.read(nbytes)
            dma, stream = self._dma(self.base + 0x24)
            if cr1 & (1 << 15) and dma:
                dma.transfer(stream, data=data)
            else:
                self.machine.fail("I2C1 read without RX DMA: not modelled", self.base + 0x24)
        else:
            dma, stream = self._dma(self.base + 0x28)
            if cr1 & (1 << 14) and dma:
                data = dma.transfer(stream, count=nbytes)
            else:
                data = b""
                self.machine.fail("I2C1 write without TX DMA: not modelled", self.base + 0x28)
            self.device.write(data, now_ns)
        self.transactions.append((address, "read" if reading else "write", data))
        if cr2 >> 24 & 1:
            self.isr |= self.TCR
        elif cr2 >> 25 & 1:
            self._stop()
        else:
            self.isr |= self.TC

    def next_event_ns(self):
        return self.done_at

    def irq_lines(self):
        cr1, isr = self.regs.get(0x00, 0), self.isr
        ev = (isr & self.NACKF and cr1 & 0x10) or (isr & self.STOPF and cr1 & 0x20) or \
             (isr & (self.TC | self.TCR) and cr1 & 0x40)
        return (self.IRQ_EV,) if ev else ()


class Dcmi(Block):
    """The DCMI with a sensor streaming `frames` (grey images at the sensor's resolution,
    cycled) at `fps` (see the module docs)."""

    name = "DCMI"
    IRQ = 78
    names = {0x00: "CR", 0x04: "SR", 0x08: "RIS", 0x0C: "IER", 0x10: "MIS", 0x14: "ICR",
             0x20: "CWSTRT", 0x24: "CWSIZE", 0x28: "DR"}
    FRAME, OVR = 1, 2
    CAPTURE, CM, CROP, ENABLE = 1, 2, 4, 1 << 14

    def __init__(self, frames, fps, dmas, sensor):
        super().__init__(DCMI_BASE)
        self.frames = frames  # list of (width, height, bytes)
        self.fps = fps
        self.dmas = dmas
        self.sensor = sensor
        self.ris = 0
        self.armed_at = None
        self.delivered = 0
        self.overruns = 0
        self.reference = None  # exposure x gain at which a frame file is delivered as it is
        self.scales = []  # the brightness of each delivered frame (1.0: the file as it is)
        # What the sensor does with the frame starting at a time (soak.py's dropped frames):
        # `schedule(start_ns)` returns None (the frame as usual), "skip" (no frame: the
        # sensor drops it and the capture waits for the next) or "blank" (a frame without
        # the pad, `blank_frame`). None: every frame as usual.
        self.schedule = None
        self.blank_frame = None
        # (end ns, start ns, "pad" or "blank") of each frame delivered.
        self.deliveries = []

    def brightness(self, start_ns):
        """The scale of a frame that started exposing at `start_ns` (see the module docs):
        1.0 while the sensor's own AEC runs or before any manual setting."""
        setting = self.sensor.exposure_at(start_ns)
        if setting is None:
            return 1.0
        lines, gain = setting
        if self.reference is None:
            self.reference = lines * gain * REFERENCE_OF_FIRST_SETTING
        return lines * gain / self.reference

    def read_reg(self, off):
        if off == 0x08:
            return self.ris
        if off == 0x10:
            return self.ris & self.regs.get(0x0C, 0)
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        if off == 0x14:
            self.ris &= ~value
            return
        if off == 0x00:
            capturing = value & self.CAPTURE and value & self.ENABLE
            if capturing and self.armed_at is None:
                self.armed_at = self.machine.time_ns
            elif not capturing:
                self.armed_at = None
        self.regs[off] = value

    def _frame_start(self):
        """Start of the first whole frame after arming: frames start every period."""
        period = 1e9 / self.fps
        return (int(self.armed_at // period) + 1) * period

    def _frame_end(self):
        """End of that frame: it is read out for 90 % of the period (the rest is vertical
        blanking)."""
        return self._frame_start() + 0.9e9 / self.fps

    def next_event_ns(self):
        return self._frame_end() if self.armed_at is not None else None

    def advance(self, now_ns):
        if self.armed_at is None or now_ns < self._frame_end():
            return
        kind = self.schedule(self._frame_start()) if self.schedule else None
        if kind == "skip":
            # Nothing arrives: the capture stays armed for the frame after this one.
            self.armed_at = self._frame_end()
            return
        width, height, pixels = (self.blank_frame if kind == "blank" else
                                 self.frames[self.delivered % len(self.frames)])
        self.deliveries.append((self._frame_end(), self._frame_start(),
                                "blank" if kind == "blank" else "pad"))
        self.delivered += 1
        scale = self.brightness(self._frame_start())
        self.scales.append(scale)
        if scale != 1.0:
            pixels = pixels.translate(bytes(min(255, round(v * scale)) for v in range(256)))
        data = self._window(width, height, pixels)
        dma = stream = None
        for candidate in self.dmas:
            stream = candidate.find(self.base + 0x28)
            if stream is not None:
                dma = candidate
                break
        if dma is None:
            self.ris |= self.OVR
            self.overruns += 1
        else:
            room = (dma.reg(stream, 0x04) & 0xFFFF) * 4
            dma.transfer(stream, data=data[:room])
            if len(data) > room:
                self.ris |= self.OVR
                self.overruns += 1
        self.ris |= self.FRAME
        cr = self.regs.get(0x00, 0)
        if cr & self.CM:
            self.regs[0x00] = cr & ~self.CAPTURE
            self.armed_at = None
        else:
            self.armed_at = self._frame_end()

    def _window(self, width, height, pixels):
        """The captured bytes: the crop window (CWSTRT.VST lines down, CWSIZE.VLINE + 1 lines of
        (CAPCNT + 1) / 2 pixels, two pixel clocks per pixel in YUV) or the whole frame."""
        if not self.regs.get(0x00, 0) & self.CROP:
            return pixels
        vst = (self.regs.get(0x20, 0) >> 16) & 0x1FFF
        hoff = (self.regs.get(0x20, 0) & 0x3FFF) // 2
        lines = ((self.regs.get(0x24, 0) >> 16) & 0x3FFF) + 1
        cols = ((self.regs.get(0x24, 0) & 0x3FFF) + 1) // 2
        rows = [pixels[(vst + r) * width + hoff:(vst + r) * width + hoff + cols]
                for r in range(min(lines, height - vst))]
        return b"".join(rows)

    def irq_lines(self):
        return (self.IRQ,) if self.ris & self.regs.get(0x0C, 0) & 0x1F else ()
