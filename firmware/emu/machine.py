"""The emulated STM32H743: unicorn's Cortex-M7 with the chip's memory map, the register models
on the bus, the exception model, emulated time, and the boot-phase checks.

Time: the core is taken to retire one instruction per cycle at the clock the RCC model says it
runs at (HSI 64 MHz until the PLL is switched in). unicorn runs in slices of a fixed number of
instructions; peripherals are brought up to date and pending interrupts are taken between
slices (so interrupt latency and the resolution of a timer read within a slice is one slice,
a few microseconds). When the executor idles in WFE with nothing to do, time jumps to the next
peripheral event (timer compare, end of an I2C transfer or a frame, a UART byte).
"""

import struct

from unicorn import (
    Uc, UcError, UC_ARCH_ARM, UC_MODE_THUMB, UC_HOOK_CODE, UC_HOOK_MEM_WRITE,
    UC_HOOK_MEM_UNMAPPED, UC_HOOK_MEM_PROT, UC_HOOK_INTR, UC_PROT_READ, UC_PROT_EXEC, UC_PROT_ALL,
)
from unicorn.arm_const import UC_CPU_ARM_CORTEX_M7, UC_ARM_REG_PC, UC_ARM_REG_SP

from . import memmap
from .bus import Bus, EmuFailure
from .system import Exceptions, Scs, Dwt, DWT_BASE
from .rcc import switch_problems

WFE, WFI, SEV = 0xBF20, 0xBF30, 0xBF40
HINTS = {WFE: "wait", WFI: "wait", SEV: "event"}
# The emulator implements WFE/WFI/SEV by replacing them, in its copy of flash, with BKPT
# instructions (a debugger's software breakpoints; the ELF is not changed): a trap costs only
# when executed, whereas any code hook makes unicorn keep the pc up to date on every
# instruction (its FAQ, "Why is my execution so slow?"). Only halfwords that the ELF's
# mapping symbols show to start an instruction are patched (`ElfImage.thumb_hint_sites`): the
# same bits can be the second half of a 32-bit instruction, which a patch would change (a
# `b.w` whose offset ends in 0xBF40 once branched 190 bytes short and hung the boot). Where
# that cannot be known, a code hook on that one address performs the hint instead.
TRAP = {"wait": 0xBEE0, "event": 0xBEE1}
EXCP_BKPT = 7
# A branch to an EXC_RETURN value (0xFFFF_FF00 and above) ends in unicorn (QEMU) as a
# prefetch abort (3) or its internal "exception exit" (8); the emulator then performs the
# exception return itself (system.Exceptions).
EXCP_RETURNS = (3, 8)
EXC_RETURN_MIN = 0xFFFF_FF00
STACK_PAINT = 0x5AC3_A55C
AXI_FILL = 0xA5  # uninitialised RAM is not zero on the chip


class Machine:
    """One firmware image on the emulated chip."""

    def __init__(self, elf, slice_len=20_000, spin_bound=100_000):
        self.elf = elf
        self.slice_len = slice_len
        # Not UC_MODE_MCLASS: with it unicorn 2.1 always builds a Cortex-M33, whose FPU has
        # no double precision (the firmware's libm needs it). The Cortex-M7 model is an
        # M-profile core of its own.
        self.uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB)
        self.uc.ctl_set_cpu_model(UC_CPU_ARM_CORTEX_M7)
        self.failure = None
        self.finished = None
        self.event = False
        self.time_ns = 0.0
        self.cycle_count = 0.0
        self.instructions = 0
        self.main_at = None
        self.stop_at_first_idle = True
        self.idled = False  # the executor has slept in WFE with nothing to do at least once
        self.hints = {}  # address -> "wait" (WFE, WFI) or "event" (SEV)
        self.traps = set()  # the hints replaced by a BKPT
        self.exc = Exceptions(self)
        self.scb = Scs(self.exc)
        self.periph = Bus(self, spin_bound)
        self.system = Bus(self, spin_bound)
        self.system.add(self.scb)
        self.system.add(Dwt(DWT_BASE))
        self.rcc = self.pwr = self.flash = self.syscfg = None
        self._mapped_sram = set()
        self._boot_hooks = []
        self._pre_main_count = 0
        self._map_memory()
        self._add_hooks()

    # --- set-up -------------------------------------------------------------------------

    def _map_memory(self):
        uc = self.uc
        for region in memmap.MEMORIES:
            if region.clock_bit is not None:
                continue
            prot = UC_PROT_READ | UC_PROT_EXEC if region is memmap.FLASH else UC_PROT_ALL
            uc.mem_map(region.base, region.size, prot)
        uc.mem_write(memmap.FLASH.base, bytes([memmap.FLASH_ERASED]) * memmap.FLASH.size)
        uc.mem_write(memmap.AXISRAM.base, bytes([AXI_FILL]) * memmap.AXISRAM.size)
        for addr, data in self.elf.segments:
            if memmap.region_of(addr) is not memmap.FLASH:
                raise EmuFailure(f"a loadable segment at {addr:#x} is not in flash")
            uc.mem_write(addr, data)
        self.stack_end = self.elf.sym("_stack_end")
        self.stack_start = self.elf.sym("_stack_start")
        words = (self.stack_start - self.stack_end) // 4
        uc.mem_write(self.stack_end, struct.pack("<I", STACK_PAINT) * words)
        uc.mmio_map(memmap.PERIPHERALS.base, memmap.PERIPHERALS.size,
                    self._mmio_read(self.periph, memmap.PERIPHERALS.base), None,
                    self._mmio_write(self.periph, memmap.PERIPHERALS.base), None)
        uc.mmio_map(memmap.SYSTEM.base, memmap.SYSTEM.size,
                    self._mmio_read(self.system, memmap.SYSTEM.base), None,
                    self._mmio_write(self.system, memmap.SYSTEM.base), None)

    @staticmethod
    def _mmio_read(bus, base):
        return lambda uc, off, size, _ud: bus.read(base + off, size)

    @staticmethod
    def _mmio_write(bus, base):
        return lambda uc, off, size, value, _ud: bus.write(base + off, size, value)

    def _add_hooks(self):
        uc = self.uc
        uc.hook_add(UC_HOOK_MEM_UNMAPPED, self._on_unmapped)
        uc.hook_add(UC_HOOK_MEM_PROT, self._on_protected)
        uc.hook_add(UC_HOOK_INTR, self._on_interrupt)
        for opcode, kind in HINTS.items():
            for addr, sure in self.elf.thumb_hint_sites(opcode):
                self.hints[addr] = kind
                if sure:
                    uc.mem_write(addr, TRAP[kind].to_bytes(2, "little"))
                    self.traps.add(addr)
                else:
                    uc.hook_add(UC_HOOK_CODE, self._on_hint, begin=addr, end=addr)
        flash = memmap.FLASH
        self._boot_hooks = [
            uc.hook_add(UC_HOOK_CODE, self._count_pre_main, begin=flash.base, end=flash.end - 1),
            uc.hook_add(UC_HOOK_MEM_WRITE, self._check_pre_main_write,
                        begin=0, end=memmap.BACKUP_SRAM.end - 1),
        ]
        main = self.elf.sym("main") & ~1
        self._main_hook = uc.hook_add(UC_HOOK_CODE, self._on_main, begin=main, end=main)

    def add_block(self, block):
        """Puts a peripheral model on the bus."""
        return self.periph.add(block)

    # --- failures and state -------------------------------------------------------------

    def pc(self):
        return self.uc.reg_read(UC_ARM_REG_PC)

    def fail(self, message, addr=None):
        """Records the first failure (with pc, function and address) and stops the CPU."""
        if self.failure is None:
            pc = self.pc()
            where = self.elf.where(pc)
            at = f", address {addr:#010x}" if addr is not None else ""
            self.failure = f"{message}: {where}{at}"
        self.uc.emu_stop()

    def finish(self, reason):
        if self.finished is None:
            self.finished = reason
        self.uc.emu_stop()

    def cycles(self):
        return int(self.cycle_count)

    def cpu_hz(self):
        return self.rcc.clocks()["cpu"]

    def irq_lines(self):
        lines = set()
        for block in self.periph.blocks:
            lines.update(block.irq_lines())
        return lines

    def sram123_clocks(self, ahb2enr):
        """Maps SRAM1-3 while RCC_AHB2ENR clocks them (unmapped, an access faults)."""
        for region in (memmap.SRAM1, memmap.SRAM2, memmap.SRAM3):
            on = bool(ahb2enr >> region.clock_bit & 1)
            if on and region not in self._mapped_sram:
                self.uc.mem_map(region.base, region.size, UC_PROT_ALL)
                self._mapped_sram.add(region)
            elif not on and region in self._mapped_sram:
                self.uc.mem_unmap(region.base, region.size)
                self._mapped_sram.discard(region)

    def mapped(self, addr, size):
        """Whether [addr, addr + size) is RAM the bus can reach now (SRAM1-3 only while
        clocked)."""
        end = addr + size
        while addr < end:
            region = memmap.region_of(addr)
            if region is None or region is memmap.FLASH or \
                    (region.clock_bit is not None and region not in self._mapped_sram):
                return False
            addr = region.end
        return True

    def clock_switch_check(self, sw):
        for problem in switch_problems(self.rcc, self.pwr, self.flash, self.syscfg, sw):
            self.fail(f"SYSCLK switch to source {sw}: {problem}", self.rcc.base + 0x10)

    def check_stack(self, sp):
        if sp < self.stack_end:
            self.fail(f"stack overflow: sp {sp:#x} below _stack_end {self.stack_end:#x}", sp)

    def stack_high_water(self):
        """Bytes of stack ever used (the painted words that are no longer paint)."""
        data = self.uc.mem_read(self.stack_end, self.stack_start - self.stack_end)
        paint = struct.pack("<I", STACK_PAINT)
        for i in range(0, len(data), 4):
            if data[i:i + 4] != paint:
                return self.stack_start - (self.stack_end + i)
        return 0

    # --- hooks --------------------------------------------------------------------------

    def _on_unmapped(self, uc, access, addr, size, value, _ud):
        kind = {19: "read", 20: "write", 21: "fetch"}.get(access, f"access {access}")
        self.fail(f"{kind} of unmapped memory", addr)
        return False

    def _on_protected(self, uc, access, addr, size, value, _ud):
        self.fail("write to read-only memory (flash)", addr)
        return False

    def _on_interrupt(self, uc, intno, _ud):
        pc = self.pc()
        if intno in EXCP_RETURNS and pc >= EXC_RETURN_MIN:
            self.exc.exception_return(pc | 1)
            return
        if intno == EXCP_BKPT and pc in self.traps:
            self._hint(pc)
            return
        self.fail(f"CPU exception {intno} (UDF/BKPT/SVC or a fault: unicorn's EXCP number)")

    def _on_hint(self, uc, addr, size, _ud):
        """A hooked WFE, WFI or SEV is about to execute (see `HINTS`)."""
        self._hint(addr)

    def _hint(self, addr):
        """Performs the WFE, WFI or SEV at `addr` (trapped or hooked) and goes on after it
        (unicorn resumes at the pc written here)."""
        self.uc.reg_write(UC_ARM_REG_PC, (addr + 2) | 1)
        if self.hints[addr] == "event":
            self.event = True
        else:
            self._wait(addr + 2)

    def _count_pre_main(self, uc, addr, size, _ud):
        self._pre_main_count += 1

    def _check_pre_main_write(self, uc, access, addr, size, value, _ud):
        sym = self.elf.sym
        sp = uc.reg_read(UC_ARM_REG_SP)
        allowed = (sym("__sbss") <= addr and addr + size <= sym("__ebss")) or \
                  (sym("__sdata") <= addr and addr + size <= sym("__edata")) or \
                  (sp - 256 <= addr and addr + size <= self.stack_start)
        if not allowed:
            self.fail(f"reset handler wrote {size} bytes outside .bss/.data/stack", addr)

    def _on_main(self, uc, addr, size, _ud):
        self.main_at = self._pre_main_count
        for hook in self._boot_hooks + [self._main_hook]:
            uc.hook_del(hook)
        self._boot_hooks = []

    def _wait(self, resume):
        """WFE/WFI: returns at once if an event is latched; else the CPU sleeps until an
        interrupt: time jumps to the next peripheral event."""
        if self.event:
            self.event = False
            return
        self.periph.reset_spin()
        self.system.reset_spin()
        while True:
            self.advance_peripherals()
            if self.exc.maybe_take(resume):
                return
            if not self.idled:
                self.idled = True
                if self.stop_at_first_idle:
                    self.finish("idle: every task at an await, no interrupt pending")
                    return
            when = [t for t in (b.next_event_ns() for b in self.periph.blocks) if t is not None]
            if not when:
                self.finish("idle: no interrupt pending and no peripheral event to come")
                return
            if min(when) <= self.time_ns:
                self.fail("a peripheral model reports an event in the past (emulator bug)")
                return
            self.time_ns = min(when)

    # --- running ------------------------------------------------------------------------

    def advance_peripherals(self):
        for block in self.periph.blocks:
            block.advance(self.time_ns)

    def reset(self):
        sp, reset = struct.unpack("<II", self.uc.mem_read(memmap.FLASH.base, 8))
        self.uc.reg_write(UC_ARM_REG_SP, sp)
        self.scb.regs[0xD08] = memmap.FLASH.base
        return reset

    def run(self, until_ns, start_pc):
        """Runs from `start_pc` until emulated time `until_ns`, a failure or `finish`."""
        pc = start_pc
        while self.failure is None and self.finished is None and self.time_ns < until_ns:
            if self.exc.maybe_take(pc):
                pc = self.pc()
            hz = self.cpu_hz()
            try:
                self.uc.emu_start(pc | 1, 0xFFFF_FFFF, count=self.slice_len)
            except UcError as e:
                if self.failure is None:
                    self.fail(f"unicorn: {e}")
                break
            self.instructions += self.slice_len
            self.cycle_count += self.slice_len
            self.time_ns += self.slice_len * 1e9 / hz
            self.advance_peripherals()
            pc = self.pc()

