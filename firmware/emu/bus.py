"""Register-level models of memory-mapped blocks and the bus that routes accesses to them.

Every block is a register file: a register reads back what was last written (from its reset
value), unless the block's model gives it behaviour (ready bits that follow enable bits, flags
set by emulated hardware, write-1-to-clear, key registers). The bus is strict where the chip is:
an access to an address no block claims is a failure, reported with the pc, the function and
the address, as is a status register that the firmware reads over and over from the same place
without its value ever changing (a spin that real hardware might end, but this model never
will: either the model lacks a behaviour or the firmware waits for something that does not
happen).
"""


class EmuFailure(Exception):
    """The firmware did something the chip would not allow, or never got where it must."""


class Block:
    """A peripheral's register file. Subclasses add behaviour in `read_reg` / `write_reg`."""

    name = "?"
    size = 0x400
    # Offset -> register name, for messages and logs.
    names = {}
    # Offset -> reset value (others reset to 0).
    reset = {}

    def __init__(self, base, name=None):
        self.base = base
        if name:
            self.name = name
        self.regs = dict(self.reset)
        self.machine = None
        self.log = None  # list of (pc, offset, value) writes, when a block records them

    def reg_name(self, off):
        return f"{self.name}.{self.names.get(off, f'+{off:#05x}')}"

    def read_reg(self, off):
        """Value the firmware reads at word offset `off`."""
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        """The firmware writes `value` (a whole word) at word offset `off`."""
        self.regs[off] = value

    def irq_lines(self):
        """IRQ numbers this block asserts right now (level-sensitive, as on the chip)."""
        return ()

    def next_event_ns(self):
        """Emulated time (ns) of this block's next own state change, or None."""
        return None

    def advance(self, now_ns):
        """Brings the block's own state (timers, transfers) up to `now_ns`."""


class Bus:
    """Routes one address space (peripherals or system) to its blocks by 1 KiB page."""

    def __init__(self, machine, spin_bound):
        self.machine = machine
        self.spin_bound = spin_bound
        self.pages = {}
        self.blocks = []
        self._spin = {}

    def add(self, block):
        block.machine = self.machine
        self.blocks.append(block)
        for page in range(block.base, block.base + block.size, 0x400):
            if page in self.pages:
                raise ValueError(f"{block.name} overlaps {self.pages[page].name}")
            self.pages[page] = block
        return block

    def _block(self, addr, what):
        block = self.pages.get(addr & ~0x3FF)
        if block is None:
            self.machine.fail(f"{what} of unmodelled/unmapped address {addr:#010x}", addr)
        return block

    def read(self, addr, size):
        block = self._block(addr, f"{size}-byte read")
        if block is None:
            return 0
        off = addr - block.base
        word = block.read_reg(off & ~3) & 0xFFFF_FFFF
        value = (word >> (8 * (off & 3))) & ((1 << (8 * size)) - 1)
        self._check_spin(addr, value, block, off & ~3)
        return value

    def write(self, addr, size, value):
        block = self._block(addr, f"{size}-byte write {value:#x}")
        if block is None:
            return
        off = addr - block.base
        aligned = off & ~3
        if size < 4:
            shift = 8 * (off & 3)
            mask = ((1 << (8 * size)) - 1) << shift
            value = (block.regs.get(aligned, 0) & ~mask) | ((value << shift) & mask)
        if block.log is not None:
            block.log.append((self.machine.pc(), aligned, value))
        block.write_reg(aligned, value & 0xFFFF_FFFF)

    def reset_spin(self):
        """Forgets the spin counts: the firmware yielded (it idles in WFE), so it is not
        spinning."""
        self._spin.clear()

    def _check_spin(self, addr, value, block, off):
        key = (self.machine.pc(), addr)
        last = self._spin.get(key)
        if last is not None and last[0] == value:
            last[1] += 1
            if last[1] > self.spin_bound:
                self.machine.fail(
                    f"spin: {last[1]} reads of {block.reg_name(off)} ({addr:#010x}) = {value:#x} "
                    "from the same pc without a change", addr)
                last[1] = 0
        else:
            self._spin[key] = [value, 0]
