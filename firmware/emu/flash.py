"""The embedded flash interface (RM0433 chapter 4, "Embedded flash memory"): the wait states the
clock set-up programs (ACR), and the program and erase operations the firmware's parameter
store performs on bank 2, with the flash interrupt that ends each.

Why this is modelled: the parameters a user sets over MAVLink are saved to the last two sectors
of bank 2 (firmware/src/param_store.rs, with embassy-stm32's async flash driver) and read back
at the next boot. Without a model that path never runs in the emulator (the sectors read erased
and any write is a failure), so a driver update, an interrupt binding or a change of the store
could break the one thing users set once and expect to keep.

Modelled, per bank (bank 1 at +0x000, bank 2 at +0x100; ACR is shared):
- KEYR: 0x45670123 then 0xCDEF89AB clears CR.LOCK; any other value is a failure (the chip
  raises a bus error and keeps the bank locked until reset). CR.LOCK written 1 locks it again.
  CR writes while locked are ignored, as on the chip; one that would start an operation is a
  failure.
- Erase: CR.SER with the sector in SNB and START: SR.BSY and QW for the erase time, then the
  sector reads 0xFF and SR.EOP is set.
- Program: with CR.PG set, 32-bit writes to the bank fill the 256-bit write buffer of one flash
  word (SR.WBNE); the eighth starts programming (SR.QW, BSY) for the program time, then SR.EOP.
  A flash word can be programmed once after an erase (its ECC allows no second value; only
  all-zero may be written over data): a second program of other data is a failure, as are a
  write to another flash word before the buffer was complete (INCERR on the chip), a write
  of another size or without PG, and one to bank 1, where the code runs (that stays
  read-only memory).
- SR is read-only (writes ignored); CCR clears SR's flags; the flash interrupt (IRQ 4) is
  asserted while EOP is set with CR.EOPIE, or OPERR with OPERRIE, in either bank.
Not modelled: option bytes, write protection, read-out protection, ECC errors on read, the
CRC unit, bank swapping, PSIZE's effect on the times. The times are fixed: an erase takes
1.1 s (ST's typical figure for a 128 KiB sector at x32 parallelism, which the firmware's
driver uses; the maximum is 2.2 s) and a flash word 50 µs (short of anything the firmware
waits for; not a datasheet figure).
"""

from unicorn import UC_HOOK_MEM_WRITE, UC_PROT_ALL, UC_PROT_EXEC, UC_PROT_READ

from . import memmap
from .bus import Block

FLASH_BASE = 0x5200_2000
FLASH_IRQ = 4
BANK_SIZE = 1024 * 1024
SECTOR_SIZE = 128 * 1024
FLASH_WORD = 32
KEYS = (0x4567_0123, 0xCDEF_89AB)
ERASE_NS = 1.1e9
PROGRAM_NS = 50e3

# FLASH_CRx bits.
CR_LOCK = 1 << 0
CR_PG = 1 << 1
CR_SER = 1 << 2
CR_START = 1 << 7
CR_EOPIE = 1 << 16
CR_OPERRIE = 1 << 22
# FLASH_SRx bits (CCRx clears the flags at the same positions).
SR_BSY = 1 << 0
SR_WBNE = 1 << 1
SR_QW = 1 << 2
SR_EOP = 1 << 16
SR_OPERR = 1 << 22
SR_FLAGS = 0x0FFF_0000


class Bank:
    """One bank's registers and its operation in progress."""

    def __init__(self, index):
        self.index = index
        self.base = memmap.FLASH.base + index * BANK_SIZE
        self.locked = True
        self.key_step = 0
        self.cr = 0x31  # LOCK, PSIZE x64: the reset value
        self.flags = 0  # SR bits 16 and up
        self.buffer_word = None  # address of the flash word being filled
        self.buffer = {}  # offset in the word -> the 32-bit value written
        self.before = b""  # the flash word's content before its first buffered write
        self.busy_until = None
        self.operation = None  # ("erase", sector) or ("program", word address, data)


class Flash(Block):
    """FLASH registers (ACR, KEYR, CR, SR, CCR of both banks) with erase and program."""

    name = "FLASH"
    names = {0x00: "ACR", 0x04: "KEYR1", 0x0C: "CR1", 0x10: "SR1", 0x14: "CCR1",
             0x104: "KEYR2", 0x10C: "CR2", 0x110: "SR2", 0x114: "CCR2", 0x18: "OPTCR"}
    reset = {0x00: 0x37, 0x18: 0x1}

    def __init__(self):
        super().__init__(FLASH_BASE)
        self.log = []
        self.banks = [Bank(0), Bank(1)]
        self.erased = []  # (time ns, bank, sector) per completed erase
        self.programmed = []  # (time ns, address) per flash word programmed
        self._writable = set()  # banks whose memory is open to program writes

    def attach(self, machine):
        """Hooks the writes to bank 2's memory (the program operations); called once the block
        is on the machine's bus."""
        bank = self.banks[1]
        machine.uc.hook_add(UC_HOOK_MEM_WRITE, self._on_memory_write,
                            begin=bank.base, end=bank.base + BANK_SIZE - 1)

    # --- registers ----------------------------------------------------------------------

    @staticmethod
    def _bank_register(off):
        """(bank index, offset within the bank's registers) of a register offset."""
        return (1, off - 0x100) if off >= 0x100 else (0, off)

    def read_reg(self, off):
        index, reg = self._bank_register(off)
        bank = self.banks[index]
        if reg == 0x00:
            return self.regs.get(0x00, 0)
        if reg == 0x0C:
            return (bank.cr & ~(CR_LOCK | CR_START)) | (CR_LOCK if bank.locked else 0)
        if reg == 0x10:
            busy = SR_BSY | SR_QW if bank.busy_until is not None else 0
            return bank.flags | busy | (SR_WBNE if bank.buffer else 0)
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        index, reg = self._bank_register(off)
        bank = self.banks[index]
        if reg == 0x00:
            self.regs[0x00] = value
        elif reg == 0x04:
            self._key(bank, value)
        elif reg == 0x0C:
            self._control(bank, value)
        elif reg == 0x10:
            pass  # read-only on the chip (embassy writes it back unchanged)
        elif reg == 0x14:
            bank.flags &= ~(value & SR_FLAGS)
        else:
            self.regs[off] = value

    def latency(self):
        return self.regs[0x00] & 0xF, (self.regs[0x00] >> 4) & 3

    def _key(self, bank, value):
        if value == KEYS[bank.key_step] and bank.locked:
            bank.key_step += 1
            if bank.key_step == len(KEYS):
                bank.locked, bank.key_step = False, 0
            return
        self.machine.fail(f"FLASH KEYR{bank.index + 1}: {value:#010x} is not the next key "
                          "(the chip keeps the bank locked until reset)", self.base + 4)

    def _control(self, bank, value):
        if bank.locked:
            if value & (CR_START | CR_PG):
                self.machine.fail(f"FLASH CR{bank.index + 1}: program/erase asked while the "
                                  "bank is locked (the chip ignores it)", self.base)
            return
        if bank.cr & CR_PG and not value & CR_PG and bank.buffer:
            self.machine.fail(f"FLASH CR{bank.index + 1}: PG cleared with a flash word half "
                              "written", self.base)
        bank.cr = value & ~CR_START
        if value & CR_LOCK:
            bank.locked = True
        self._open_for_program(bank, bool(bank.cr & CR_PG) and not bank.locked)
        if value & CR_START:
            if not value & CR_SER:
                self.machine.fail(f"FLASH CR{bank.index + 1}: START without SER (bank erase is "
                                  "not modelled)", self.base)
            elif bank.busy_until is not None:
                self.machine.fail(f"FLASH CR{bank.index + 1}: erase started while busy",
                                  self.base)
            else:
                sector = (value >> 8) & 7
                bank.operation = ("erase", sector)
                bank.busy_until = self.machine.time_ns + ERASE_NS

    def _open_for_program(self, bank, open_):
        """Bank 2's memory is writable while its CR.PG is set (the writes are program
        operations, see `_on_memory_write`); read-only otherwise. Bank 1 always stays
        read-only: a write there is the machine's read-only failure."""
        if bank.index != 1 or open_ == (bank.index in self._writable):
            return
        prot = UC_PROT_ALL if open_ else UC_PROT_READ | UC_PROT_EXEC
        self.machine.uc.mem_protect(bank.base, BANK_SIZE, prot)
        if open_:
            self._writable.add(bank.index)
        else:
            self._writable.discard(bank.index)

    # --- program writes -----------------------------------------------------------------

    def _on_memory_write(self, uc, access, addr, size, value, _ud):
        """A store to bank 2's memory while it is open (CR2.PG): one 32-bit word of a flash
        word's write buffer. The store itself also lands in memory (unicorn performs it after
        this hook); the flash word is written again, whole, when it is programmed."""
        bank = self.banks[1]
        if size != 4 or addr % 4:
            self.machine.fail(f"flash program write of {size} bytes at {addr:#x} (the driver "
                              "programs 32-bit words)", addr)
            return
        if bank.busy_until is not None:
            self.machine.fail("flash program write while the bank is busy", addr)
            return
        word = addr - addr % FLASH_WORD
        if bank.buffer_word is not None and word != bank.buffer_word:
            self.machine.fail(f"flash program write to {addr:#x} before the flash word at "
                              f"{bank.buffer_word:#x} was complete (INCERR)", addr)
            return
        if bank.buffer_word is None:
            # The word as it was: this hook runs before the store lands in memory.
            bank.buffer_word, bank.before = word, bytes(uc.mem_read(word, FLASH_WORD))
        bank.buffer[addr - word] = value & 0xFFFF_FFFF
        if len(bank.buffer) < FLASH_WORD // 4:
            return
        data = b"".join(bank.buffer[k].to_bytes(4, "little") for k in range(0, FLASH_WORD, 4))
        if bank.before != bytes([memmap.FLASH_ERASED]) * FLASH_WORD and any(data):
            self.machine.fail(f"flash word at {word:#x} programmed a second time without an "
                              "erase (its ECC would be corrupt)", word)
            return
        bank.buffer_word, bank.buffer = None, {}
        bank.operation = ("program", word, data)
        bank.busy_until = self.machine.time_ns + PROGRAM_NS

    # --- power cut ----------------------------------------------------------------------

    def kept_at_power_off(self):
        """The whole flash as a power cut now leaves it (soak.py's brown-outs): what the
        memory holds, except a flash word whose program had not completed: its write buffer
        still filling, or its programming under way. Those keep their content from before
        (the buffer is volatile; a word cut while it programs could also come out half
        written, with an ECC error on read, which this model does not produce). An erase
        under way leaves its sector as it was (the model erases at the end)."""
        image = bytearray(self.machine.uc.mem_read(memmap.FLASH.base, memmap.FLASH.size))
        for bank in self.banks:
            word = bank.buffer_word
            if word is None and bank.operation is not None and bank.operation[0] == "program":
                word = bank.operation[1]
            if word is not None:
                offset = word - memmap.FLASH.base
                image[offset:offset + FLASH_WORD] = bank.before
        return bytes(image)

    # --- time ---------------------------------------------------------------------------

    def advance(self, now_ns):
        for bank in self.banks:
            if bank.busy_until is None or now_ns < bank.busy_until:
                continue
            operation = bank.operation
            if operation[0] == "erase":
                sector = operation[1]
                base = bank.base + sector * SECTOR_SIZE
                self.machine.uc.mem_write(base, bytes([memmap.FLASH_ERASED]) * SECTOR_SIZE)
                self.erased.append((bank.busy_until, bank.index, sector))
            else:
                _, word, data = operation
                self.machine.uc.mem_write(word, data)
                self.programmed.append((bank.busy_until, word))
            bank.busy_until, bank.operation = None, None
            bank.flags |= SR_EOP

    def next_event_ns(self):
        times = [b.busy_until for b in self.banks if b.busy_until is not None]
        return min(times) if times else None

    def irq_lines(self):
        for bank in self.banks:
            if (bank.flags & SR_EOP and bank.cr & CR_EOPIE) or \
                    (bank.flags & SR_OPERR and bank.cr & CR_OPERRIE):
                return (FLASH_IRQ,)
        return ()
