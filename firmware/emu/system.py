"""The Cortex-M7's system space: the System Control Space (SCB, NVIC, SysTick, MPU, FPU, cache
maintenance, CoreDebug) and the DWT, as register files with the behaviour the firmware needs,
plus the exception model that unicorn lacks.

unicorn emulates the core's instructions but not its NVIC: here the emulator keeps the
interrupt state (enabled, pending, active, priorities) and performs exception entry and return
itself (see `Exceptions`). Caches are not modelled (the emulator's memory is always coherent),
so the cache maintenance registers accept writes and do nothing; CCSIDR describes the M7's
16 KiB 4-way D-cache and 16 KiB 2-way I-cache so that cortex-m's set/way loops terminate.
"""

from unicorn.arm_const import (
    UC_ARM_REG_LR, UC_ARM_REG_PC, UC_ARM_REG_PRIMASK, UC_ARM_REG_BASEPRI, UC_ARM_REG_FAULTMASK,
    UC_ARM_REG_R0, UC_ARM_REG_R1, UC_ARM_REG_R2, UC_ARM_REG_R3, UC_ARM_REG_R12, UC_ARM_REG_SP,
    UC_ARM_REG_XPSR, UC_ARM_REG_FPSCR, UC_ARM_REG_S0,
)

from .bus import Block

SCS_BASE = 0xE000_E000
DWT_BASE = 0xE000_1000
IRQ_BASE = 16  # exception number of IRQ 0
NUM_IRQS = 150

# EXC_RETURN values with an extended (FP) frame: back to thread mode on MSP, or to a handler.
EXC_RETURN_THREAD = 0xFFFF_FFE9
EXC_RETURN_HANDLER = 0xFFFF_FFE1
# Exception frame: r0-r3, r12, lr, pc, xpsr, then s0-s15, fpscr and one reserved word.
BASIC_REGS = (UC_ARM_REG_R0, UC_ARM_REG_R1, UC_ARM_REG_R2, UC_ARM_REG_R3, UC_ARM_REG_R12,
              UC_ARM_REG_LR, UC_ARM_REG_PC, UC_ARM_REG_XPSR)
FRAME_WORDS = 8 + 16 + 2
XPSR_T = 1 << 24
XPSR_ALIGNED = 1 << 9  # the frame was realigned to 8 bytes on entry
XPSR_IT_MASK = (0b11 << 25) | (0b111111 << 10)


class Exceptions:
    """NVIC state and exception entry/return.

    The core stays in thread mode as far as unicorn knows (its IPSR stays 0): a handler's
    branch to an EXC_RETURN value makes unicorn raise its internal exception-exit interrupt,
    on which the machine calls `exception_return` to unstack the frame. The FP context is always
    stacked (the extended frame): lazy stacking only defers those stores, which software cannot
    observe apart from FPCAR, which the firmware does not read.
    """

    def __init__(self, machine):
        self.machine = machine
        self.uc = machine.uc
        self.enabled = set()
        self.pending = set()      # software-pended (ISPR/ICSR) exception numbers
        self.active = []          # stack of active exception numbers
        self.prio = [0] * (IRQ_BASE + NUM_IRQS)
        self.taken = {}           # exception number -> times taken

    def priority(self, exc):
        return self.prio[exc] if exc >= 4 else -1

    def current_priority(self):
        prio = 256
        if self.active:
            prio = min(self.priority(e) for e in self.active)
        basepri = self.uc.reg_read(UC_ARM_REG_BASEPRI) & 0xFF
        if basepri:
            prio = min(prio, basepri)
        if self.uc.reg_read(UC_ARM_REG_FAULTMASK) & 1:
            prio = -1
        elif self.uc.reg_read(UC_ARM_REG_PRIMASK) & 1:
            prio = min(prio, 0)
        return prio

    def asserted(self):
        """Pending exception numbers: software-pended ones and the IRQ lines peripherals hold."""
        lines = {IRQ_BASE + irq for irq in self.machine.irq_lines()}
        return (self.pending | lines) - set(self.active)

    def next_to_take(self):
        """The pending, enabled exception that would preempt now, or None."""
        best = None
        for exc in self.asserted():
            if exc >= IRQ_BASE and (exc - IRQ_BASE) not in self.enabled:
                continue
            if best is None or (self.priority(exc), exc) < (self.priority(best), best):
                best = exc
        if best is None or self.priority(best) >= self.current_priority():
            return None
        return best

    def in_it_block(self):
        return bool(self.uc.reg_read(UC_ARM_REG_XPSR) & XPSR_IT_MASK)

    def maybe_take(self, return_pc):
        """Takes the most urgent takeable exception, returning to `return_pc` afterwards.
        Returns True if one was taken (the pc is then the handler's first instruction)."""
        exc = self.next_to_take()
        if exc is None or self.in_it_block():
            return False
        self.enter(exc, return_pc)
        return True

    def enter(self, exc, return_pc):
        uc = self.uc
        values = [uc.reg_read(r) for r in BASIC_REGS]
        values[6] = return_pc & ~1
        values[7] = (values[7] & ~XPSR_IT_MASK) | XPSR_T
        fp = [uc.reg_read(UC_ARM_REG_S0 + i) for i in range(16)]
        fp.append(uc.reg_read(UC_ARM_REG_FPSCR))
        fp.append(0)
        sp = uc.reg_read(UC_ARM_REG_SP)
        frame = (sp - 4 * FRAME_WORDS) & ~7
        if sp & 4:
            values[7] |= XPSR_ALIGNED
        words = values + fp
        self.machine.check_stack(frame)
        uc.mem_write(frame, b"".join((w & 0xFFFF_FFFF).to_bytes(4, "little") for w in words))
        uc.reg_write(UC_ARM_REG_SP, frame)
        uc.reg_write(UC_ARM_REG_LR, EXC_RETURN_HANDLER if self.active else EXC_RETURN_THREAD)
        uc.reg_write(UC_ARM_REG_XPSR, XPSR_T)
        self.pending.discard(exc)
        self.active.append(exc)
        self.taken[exc] = self.taken.get(exc, 0) + 1
        vtor = self.machine.scb.regs.get(0xD08, 0)
        vector = int.from_bytes(uc.mem_read(vtor + 4 * exc, 4), "little")
        if not vector & 1:
            self.machine.fail(f"vector {exc} is {vector:#x} (not a Thumb address)", vtor + 4 * exc)
        self.machine.event = True
        uc.reg_write(UC_ARM_REG_PC, vector | 1)

    def exception_return(self, exc_return):
        uc = self.uc
        if not self.active:
            self.machine.fail(f"exception return {exc_return:#x} outside a handler", exc_return)
            return
        if exc_return not in (EXC_RETURN_THREAD, EXC_RETURN_HANDLER):
            self.machine.fail(f"unexpected EXC_RETURN {exc_return:#x}", exc_return)
            return
        self.active.pop()
        frame = uc.reg_read(UC_ARM_REG_SP)
        raw = uc.mem_read(frame, 4 * FRAME_WORDS)
        words = [int.from_bytes(raw[4 * i:4 * i + 4], "little") for i in range(FRAME_WORDS)]
        for reg, value in zip(BASIC_REGS[:6], words[:6]):
            uc.reg_write(reg, value)
        for i in range(16):
            uc.reg_write(UC_ARM_REG_S0 + i, words[8 + i])
        uc.reg_write(UC_ARM_REG_FPSCR, words[24])
        xpsr = words[7]
        sp = frame + 4 * FRAME_WORDS + (4 if xpsr & XPSR_ALIGNED else 0)
        uc.reg_write(UC_ARM_REG_SP, sp)
        uc.reg_write(UC_ARM_REG_XPSR, xpsr & ~XPSR_ALIGNED)
        return_pc = words[6]
        # Tail-chain: a pending exception is taken before the interrupted code resumes.
        if not self.maybe_take(return_pc):
            uc.reg_write(UC_ARM_REG_PC, return_pc | 1)


class Scs(Block):
    """System Control Space 0xE000_E000-0xE000_EFFF: SysTick, NVIC, SCB, MPU, CoreDebug, FPU,
    cache maintenance."""

    name = "SCS"
    size = 0x1000
    names = {0x010: "SYST_CSR", 0xD04: "ICSR", 0xD08: "VTOR", 0xD0C: "AIRCR", 0xD14: "CCR",
             0xD80: "CCSIDR", 0xD88: "CPACR", 0xD94: "MPU_CTRL", 0xF34: "FPCCR"}
    reset = {
        0xD00: 0x411F_C271,  # CPUID: Cortex-M7 r1p1
        0xD14: 0x0004_0200,  # CCR: STKALIGN, BP
        0xD78: 0x0900_0003,  # CLIDR: L1 I and D caches
        0xD7C: 0x8303_C003,  # CTR: 32-byte lines
        0xD90: 0x0000_1000,  # MPU_TYPE: 16 regions
        0xF34: 0xC000_0000,  # FPCCR: ASPEN, LSPEN
    }
    CCSIDR_D = 0xF00F_E019  # 16 KiB, 4 ways, 128 sets, 32-byte lines
    CCSIDR_I = 0xF01F_E009  # 16 KiB, 2 ways, 256 sets, 32-byte lines

    def __init__(self, exceptions):
        super().__init__(SCS_BASE)
        self.exc = exceptions
        self.cache_ops = 0

    def read_reg(self, off):
        exc = self.exc
        if 0x100 <= off < 0x120 or 0x180 <= off < 0x1A0:
            return self._bits(off & 0x1F, exc.enabled, 0)
        if 0x200 <= off < 0x220 or 0x280 <= off < 0x2A0:
            return self._bits(off & 0x1F, exc.asserted(), IRQ_BASE)
        if 0x300 <= off < 0x320:
            return self._bits(off & 0x1F, set(exc.active), IRQ_BASE)
        if 0x400 <= off < 0x400 + NUM_IRQS:
            return sum(exc.prio[IRQ_BASE + off - 0x400 + i] << (8 * i) for i in range(4))
        if off == 0xD04:
            active = exc.active[-1] if exc.active else 0
            return active | (bool(exc.asserted()) << 22)
        if off == 0xD0C:
            return 0xFA05_0000 | (self.regs.get(off, 0) & 0x700)
        if off == 0xD80:
            return self.CCSIDR_I if self.regs.get(0xD84, 0) & 1 else self.CCSIDR_D
        return self.regs.get(off, 0)

    @staticmethod
    def _bits(word_off, numbers, offset):
        first = 8 * word_off
        return sum(1 << (n - offset - first) for n in numbers
                   if 0 <= n - offset - first < 32)

    def _each_bit(self, off, value, base=0):
        first = 8 * (off & 0x1F)
        return [base + first + i for i in range(32) if value >> i & 1]

    def write_reg(self, off, value):
        exc = self.exc
        if 0x100 <= off < 0x120:
            exc.enabled.update(self._each_bit(off, value))
        elif 0x180 <= off < 0x1A0:
            exc.enabled.difference_update(self._each_bit(off, value))
        elif 0x200 <= off < 0x220:
            exc.pending.update(self._each_bit(off, value, IRQ_BASE))
        elif 0x280 <= off < 0x2A0:
            exc.pending.difference_update(self._each_bit(off, value, IRQ_BASE))
        elif 0x400 <= off < 0x400 + NUM_IRQS:
            for i in range(4):
                exc.prio[IRQ_BASE + off - 0x400 + i] = (value >> (8 * i)) & 0xFF
        elif 0xD18 <= off < 0xD24:
            for i in range(4):
                exc.prio[4 + off - 0xD18 + i] = (value >> (8 * i)) & 0xFF
            self.regs[off] = value
        elif off == 0xD04:
            self._icsr(value)
        elif off == 0xD0C:
            if value >> 16 == 0x05FA and value & 0b100:
                self.machine.fail("SYSRESETREQ: the firmware reset the chip", SCS_BASE + off)
            self.regs[off] = value
        elif off == 0x010 and value & 0b11 == 0b11:
            self.machine.fail("SysTick interrupt enabled: not modelled", SCS_BASE + off)
        elif off == 0xF00:
            exc.pending.add(IRQ_BASE + (value & 0x1FF))
        elif 0xF50 <= off <= 0xF78:
            self.cache_ops += 1
        else:
            self.regs[off] = value

    def _icsr(self, value):
        for bit, exc_no, set_it in ((31, 2, True), (28, 14, True), (27, 14, False),
                                    (26, 15, True), (25, 15, False)):
            if value >> bit & 1:
                (self.exc.pending.add if set_it else self.exc.pending.discard)(exc_no)


class Dwt(Block):
    """DWT: CYCCNT counts core cycles (from the emulated time) once enabled."""

    name = "DWT"
    names = {0x000: "CTRL", 0x004: "CYCCNT"}
    reset = {0x000: 0x4000_0000}

    def read_reg(self, off):
        if off == 0x004:
            return self.machine.cycles() & 0xFFFF_FFFF
        return self.regs.get(off, 0)
