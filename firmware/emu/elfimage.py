"""The firmware ELF as the emulator needs it: loadable segments, linker symbols, and a lookup
from an address to the (demangled) function it lies in, so every failure can name its code.

Rust's legacy symbol mangling (`_ZN` ... `E`, the default of the toolchain we use) is decoded
here rather than with an external tool: length-prefixed path segments, the trailing `h<hash>`
segment dropped, `$..$` escapes and `..` (for `::`) replaced. Other names are shown as they are.
"""

import bisect
import re

from elftools.elf.elffile import ELFFile

_ESCAPES = {
    "$SP$": "@", "$BP$": "*", "$RF$": "&", "$LT$": "<", "$GT$": ">", "$LP$": "(",
    "$RP$": ")", "$C$": ",",
}


def _unescape(segment):
    segment = re.sub(r"\$u([0-9a-f]+)\$", lambda m: chr(int(m.group(1), 16)), segment)
    for escape, char in _ESCAPES.items():
        segment = segment.replace(escape, char)
    return segment.replace("..", "::")


def demangle(name):
    """Demangles a legacy Rust symbol; returns any other name unchanged."""
    if not name.startswith("_ZN") or not name.endswith("E"):
        return name
    body, segments, i = name[3:-1], [], 0
    while i < len(body) and body[i].isdigit():
        j = i
        while body[j].isdigit():
            j += 1
        n = int(body[i:j])
        segments.append(body[j:j + n])
        i = j + n
    if segments and re.fullmatch(r"h[0-9a-f]{16}", segments[-1]):
        segments.pop()
    text = "::".join(_unescape(s) for s in segments)
    return text[1:] if text.startswith("_$") else text


def thumb_hint_sites(base, data, mapping, opcode):
    """Where the 16-bit hint `opcode` (WFE, WFI, SEV) can execute in the code `data` at `base`:
    (address, sure) for the halfwords with that encoding that may start an instruction.

    `mapping` is the ELF's sorted mapping symbols, (address, "t" | "d" | "a"): `$t` where Thumb
    code starts, `$d` where data inside code starts (ELF for the Arm Architecture, "Mapping
    symbols").
    From the `$t` before a match, a linear decode (a first halfword with 0b11101, 0b11110 or
    0b11111 in its top five bits makes a 32-bit instruction: ARMv7-M ARM, A5.1) finds whether
    an instruction starts there (`sure`) or the match is the second half of a 32-bit one
    (`b.w` can have 0xBF40 there), which is left out: it never executes as a hint, and patching
    it would change that instruction. Matches in data are left out. Without mapping symbols (a
    stripped ELF) every match is returned with `sure` false: the caller must not patch it."""
    matches = [i for i in range(0, len(data) - 1, 2) if data[i] | (data[i + 1] << 8) == opcode]
    if not mapping:
        return [(base + i, False) for i in matches]
    starts = [addr for addr, _ in mapping]
    sites = []
    # The decode goes on from the last match while the next one is in the same code region,
    # so each region is decoded once, up to its last match.
    region, at = None, 0
    for i in matches:
        m = bisect.bisect_right(starts, base + i) - 1
        if m < 0 or mapping[m][1] != "t":
            continue
        if m != region:
            region, at = m, mapping[m][0] - base
        while at < i:
            at += 4 if data[at + 1] >> 3 in (0b11101, 0b11110, 0b11111) else 2
        if at == i:
            sites.append((base + i, True))
    return sites


class ElfImage:
    """Segments and symbols of one firmware ELF."""

    def __init__(self, path):
        self.path = path
        with open(path, "rb") as f:
            elf = ELFFile(f)
            self.segments = [
                (seg["p_paddr"], seg.data())
                for seg in elf.iter_segments()
                if seg["p_type"] == "PT_LOAD" and seg["p_filesz"] > 0
            ]
            self.symbols = {}
            functions = []
            mapping = []  # (address, "t" or "d" or "a"): ARM mapping symbols
            for sym in elf.get_section_by_name(".symtab").iter_symbols():
                kind = sym.name.split(".")[0]
                if kind in ("$t", "$d", "$a"):
                    mapping.append((sym["st_value"], kind[1]))
                    continue
                if sym.name:
                    self.symbols.setdefault(sym.name, sym["st_value"])
                if sym["st_info"]["type"] == "STT_FUNC" and sym["st_value"]:
                    functions.append((sym["st_value"] & ~1, sym["st_size"], sym.name))
            self.text = self._section(elf, ".text")
        functions.sort()
        mapping.sort()
        self._mapping = mapping
        self._func_addrs = [f[0] for f in functions]
        self._funcs = functions

    @staticmethod
    def _section(elf, name):
        sec = elf.get_section_by_name(name)
        return (sec["sh_addr"], sec.data()) if sec else (0, b"")

    def sym(self, name):
        """Address of a symbol that must exist (a linker symbol or `main`)."""
        if name not in self.symbols:
            raise KeyError(f"{self.path}: no symbol {name}")
        return self.symbols[name]

    def function_at(self, addr):
        """`name+0xoff` of the function containing `addr`, or `?`."""
        i = bisect.bisect_right(self._func_addrs, addr & ~1) - 1
        if i < 0:
            return "?"
        start, size, name = self._funcs[i]
        if size and addr >= start + size:
            return "?"
        return f"{demangle(name)}+{addr - start:#x}"

    def where(self, pc):
        """A pc with its function, for messages."""
        return f"pc {pc:#010x} ({self.function_at(pc)})"

    def thumb_hint_sites(self, opcode):
        """Where the 16-bit hint `opcode` can execute in .text (see `thumb_hint_sites`)."""
        base, data = self.text
        return thumb_hint_sites(base, data, self._mapping, opcode)

    def function_addresses(self, demangled):
        """Start addresses of every function whose demangled name is `demangled`."""
        return [start for start, _, name in self._funcs if demangle(name) == demangled]

    def pools(self):
        """Embassy task pools: demangled name -> address (one TaskStorage each; its first word
        is the task's state: byte 0 spawned, byte 1 queued to run)."""
        out = {}
        for name, addr in self.symbols.items():
            d = demangle(name)
            if d.endswith("::POOL"):
                out[d[: -len("::POOL")]] = addr
        return out
