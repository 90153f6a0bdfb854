"""Reset and clock control, power control and SYSCFG (RM0433 chapters 8 "RCC", 6 "PWR", 12
"SYSCFG"), with the status bits the clock set-up waits for, and the check of the resulting
clock tree (with the flash wait states, whose register flash.py models) against what
`firmware/src/clocks.rs` asks for.

Modelled: oscillator and PLL ready bits follow their enable bits at once (HSIRDY, CSIRDY,
HSI48RDY, HSERDY, PLL1-3RDY, LSIRDY, LSERDY); SWS follows SW; D1CKRDY/D2CKRDY read 1; the
RCC_C1_* registers alias the common ones (single core); PWR_D3CR.VOSRDY and
PWR_CSR1.ACTVOSRDY read 1 and ACTVOS follows VOS; PWR_CR3's supply bits are write-once;
SYSCFG_CCCSR.READY follows EN. Not modelled: oscillator
start-up times, clock security, the PLL lock time, the PLL input/VCO ranges' effect (they are
checked instead), peripheral clock gating (except SRAM1-3, see memmap.py).

At the moment SYSCLK switches to a faster source, the model checks RM0433's order: the voltage
scale and the flash wait states must already suit the new clocks (else the chip may fail).
"""

from .bus import Block

RCC_BASE = 0x5802_4400
PWR_BASE = 0x5802_4800
SYSCFG_BASE = 0x5800_0400

HSI_HZ = 64_000_000
CSI_HZ = 4_000_000
LSI_HZ = 32_000

# RM0433 Table 17 "FLASH recommended number of wait states and programming delay":
# per VOS, (upper bound of the AXI clock in Hz, LATENCY, WRHIGHFREQ).
FLASH_TABLE = {
    0: ((70e6, 0, 0), (140e6, 1, 1), (185e6, 2, 1), (210e6, 2, 2), (225e6, 3, 2), (240e6, 4, 2)),
    1: ((70e6, 0, 0), (140e6, 1, 1), (185e6, 2, 1), (210e6, 2, 2), (225e6, 3, 2)),
    2: ((55e6, 0, 0), (110e6, 1, 1), (165e6, 2, 1), (225e6, 3, 2)),
    3: ((45e6, 0, 0), (90e6, 1, 1), (135e6, 2, 1), (180e6, 3, 2), (225e6, 4, 2)),
}
# STM32H743 datasheet, general operating conditions: maximum CPU / AXI clock per VOS.
MAX_CPU_HZ = {0: 480e6, 1: 400e6, 2: 300e6, 3: 200e6}
MAX_HCLK_HZ = {0: 240e6, 1: 200e6, 2: 150e6, 3: 100e6}

# RCC_CR enable bit -> ready bit.
CR_READY = {0: 2, 7: 8, 12: 13, 16: 17, 24: 25, 26: 27, 28: 29}
CR_D1CKRDY_D2CKRDY = (1 << 14) | (1 << 15)


def flash_wait_states(vos, axi_hz):
    """(LATENCY, WRHIGHFREQ) RM0433 gives for `axi_hz` at voltage scale `vos`, or None."""
    for limit, latency, wrhighfreq in FLASH_TABLE[vos]:
        if axi_hz <= limit:
            return latency, wrhighfreq
    return None


def ahb_div(bits):
    """HPRE / D1CPRE encoding: 0xxx = /1, 1000 = /2 ... 1111 = /512 (no /32)."""
    if bits < 8:
        return 1
    return (2, 4, 8, 16, 64, 128, 256, 512)[bits - 8]


def apb_div(bits):
    """DxPPREx encoding: 0xx = /1, 100 = /2 ... 111 = /16."""
    return 1 if bits < 4 else 1 << (bits - 3)


class Rcc(Block):
    name = "RCC"
    names = {0x00: "CR", 0x10: "CFGR", 0x18: "D1CFGR", 0x1C: "D2CFGR", 0x20: "D3CFGR",
             0x28: "PLLCKSELR", 0x2C: "PLLCFGR", 0x30: "PLL1DIVR", 0x38: "PLL2DIVR",
             0x40: "PLL3DIVR", 0x70: "BDCR", 0x74: "CSR", 0xDC: "AHB2ENR", 0xE0: "AHB4ENR"}
    reset = {0x00: 0x0000_0025, 0x28: 0x0202_0200, 0x2C: 0x01FF_0000,
             0x30: 0x0101_0280, 0x38: 0x0101_0280, 0x40: 0x0101_0280}
    C1_ALIASES = range(0x130, 0x180)

    def __init__(self, hse_hz):
        super().__init__(RCC_BASE)
        self.hse_hz = hse_hz
        self.log = []
        self.ignored = []  # writes the chip ignores in part (see _protect_plls)
        self.ready = dict(CR_READY)

    @classmethod
    def _canonical(cls, off):
        return off - 0x60 if off in cls.C1_ALIASES else off

    def read_reg(self, off):
        off = self._canonical(off)
        value = self.regs.get(off, 0)
        if off == 0x00:
            for on, ready in self.ready.items():
                value = value | (1 << ready) if value >> on & 1 else value & ~(1 << ready)
            return value | CR_D1CKRDY_D2CKRDY
        if off == 0x10:
            return (value & ~0x38) | ((value & 0x7) << 3)
        if off in (0x70, 0x74):
            return (value & ~2) | ((value & 1) << 1)
        return value

    def write_reg(self, off, value):
        off = self._canonical(off)
        value = self._protect_plls(off, value)
        if off == 0x10 and (value & 7) != (self.regs.get(0x10, 0) & 7):
            self.machine.clock_switch_check(value & 7)
        self.regs[off] = value
        if off == 0xDC:
            self.machine.sram123_clocks(value)

    def _protect_plls(self, off, value):
        """RM0433 §8.7: a PLL's DIVM, DIVN/P/Q/R, range and output enables cannot change while
        it runs (PLLxON), nor PLLSRC while any PLL runs; such writes leave those fields as they
        are (embassy's disable of an unused PLL writes the whole PLLCKSELR, which the chip
        thereby ignores for the running PLL1)."""
        cr = self.regs.get(0x00, 0)
        on = [bool(cr >> (24 + 2 * n) & 1) for n in range(3)]
        old = self.regs.get(off, 0)
        keep = 0
        if off == 0x28:
            keep = (0x3 if any(on) else 0) | sum(0x3F << (4 + 8 * n) for n in range(3) if on[n])
        elif off in (0x30, 0x38, 0x40):
            keep = 0xFFFF_FFFF if on[(off - 0x30) // 8] else 0
        elif off == 0x2C:
            keep = sum((0xF << (4 * n)) | (0x7 << (16 + 3 * n)) for n in range(3) if on[n])
        if (value ^ old) & keep and self.log is not None:
            self.ignored.append((self.machine.pc(), off, value))
        return (value & ~keep) | (old & keep)

    def inject_no_pll1rdy(self):
        """Fault injection: PLL1 never locks (PLL1RDY stays 0)."""
        del self.ready[24]

    def field(self, off, lsb, width):
        return (self.read_reg(off) >> lsb) & ((1 << width) - 1)

    def pll(self, n):
        """(reference, vco, p, q, r) of PLL n in Hz (0 for a disabled output)."""
        src = self.field(0x28, 0, 2)
        src_hz = {0: self.hsi_hz(), 1: CSI_HZ, 2: self.hse_hz, 3: 0}[src]
        divm = self.field(0x28, (4, 12, 20)[n - 1], 6)
        if not divm:
            return 0, 0, 0, 0, 0
        divr = self.read_reg(0x30 + 8 * (n - 1))
        ref = src_hz / divm
        vco = ref * ((divr & 0x1FF) + 1)
        outs = []
        for i, lsb in enumerate((9, 16, 24)):
            enabled = self.field(0x2C, 16 + 3 * (n - 1) + i, 1)
            outs.append(vco / (((divr >> lsb) & 0x7F) + 1) if enabled else 0)
        return (ref, vco, *outs)

    def hsi_hz(self):
        return HSI_HZ >> self.field(0x00, 3, 2)

    def sysclk_hz(self, sw=None):
        sw = self.field(0x10, 0, 3) if sw is None else sw
        return {0: self.hsi_hz(), 1: CSI_HZ, 2: self.hse_hz, 3: self.pll(1)[2]}.get(sw, 0)

    def clocks(self, sw=None):
        """The bus clocks in Hz: cpu, hclk, pclk1-4 and the APB1 timer clock."""
        sys_hz = self.sysclk_hz(sw)
        cpu = sys_hz / ahb_div(self.field(0x18, 8, 4))
        hclk = cpu / ahb_div(self.field(0x18, 0, 4))
        d2ppre1 = apb_div(self.field(0x1C, 4, 3))
        timpre = self.field(0x10, 15, 1)
        if timpre:
            tim1 = hclk if d2ppre1 <= 2 else 4 * hclk / d2ppre1
        else:
            tim1 = hclk if d2ppre1 == 1 else 2 * hclk / d2ppre1
        return {
            "cpu": cpu, "hclk": hclk,
            "pclk1": hclk / d2ppre1,
            "pclk2": hclk / apb_div(self.field(0x1C, 8, 3)),
            "pclk3": hclk / apb_div(self.field(0x18, 4, 3)),
            "pclk4": hclk / apb_div(self.field(0x20, 4, 3)),
            "tim_apb1": tim1,
        }


class Pwr(Block):
    name = "PWR"
    names = {0x00: "CR1", 0x04: "CSR1", 0x0C: "CR3", 0x18: "D3CR"}
    reset = {0x00: 0xF000_C000, 0x0C: 0x0000_0006, 0x18: 0x0000_4000}
    SUPPLY_BITS = 0x3F

    def __init__(self):
        super().__init__(PWR_BASE)
        self.log = []
        self.cr3_written = False

    def read_reg(self, off):
        if off == 0x04:
            return (1 << 13) | (self.regs[0x18] & (3 << 14))
        if off == 0x18:
            return self.regs[0x18] | (1 << 13)
        return self.regs.get(off, 0)

    def write_reg(self, off, value):
        if off == 0x0C:
            if self.cr3_written:
                value = (value & ~self.SUPPLY_BITS) | (self.regs[0x0C] & self.SUPPLY_BITS)
            self.cr3_written = True
        self.regs[off] = value

    def vos(self, syscfg):
        """The voltage scale: D3CR.VOS 11 = VOS1 (VOS0 with SYSCFG_PWRCR.ODEN), 10 = VOS2,
        01 = VOS3."""
        bits = (self.regs[0x18] >> 14) & 3
        scale = {3: 1, 2: 2, 1: 3, 0: 3}[bits]
        return 0 if scale == 1 and syscfg.regs.get(0x2C, 0) & 1 else scale


class Syscfg(Block):
    name = "SYSCFG"
    names = {0x20: "CCCSR", 0x2C: "PWRCR"}

    def __init__(self):
        super().__init__(SYSCFG_BASE)
        self.log = []

    def read_reg(self, off):
        value = self.regs.get(off, 0)
        if off == 0x20:
            return (value & ~(1 << 8)) | ((value & 1) << 8)
        return value


def switch_problems(rcc, pwr, flash, syscfg, sw):
    """What is wrong with switching SYSCLK to source `sw` now (RM0433 §8.5.6: raise VOS and the
    flash latency before the clock)."""
    clocks = rcc.clocks(sw)
    vos = pwr.vos(syscfg)
    problems = []
    if clocks["cpu"] > MAX_CPU_HZ[vos] or clocks["hclk"] > MAX_HCLK_HZ[vos]:
        problems.append(f"CPU {clocks['cpu'] / 1e6:.0f} MHz / HCLK {clocks['hclk'] / 1e6:.0f} MHz "
                        f"above the VOS{vos} limits")
    needed = flash_wait_states(vos, clocks["hclk"])
    latency, _ = flash.latency()
    if needed is None or latency < needed[0]:
        problems.append(f"flash LATENCY {latency} for HCLK {clocks['hclk'] / 1e6:.0f} MHz at "
                        f"VOS{vos} (RM0433 Table 17 needs {needed[0] if needed else '?'})")
    return problems


def check_clock_tree(rcc, pwr, flash, syscfg, expect):
    """Compares the programmed clock tree with `expect` (board HSE, DIVM, DIVN, VOS);
    returns (problems, summary line)."""
    got = {
        "HSEON": rcc.field(0x00, 16, 1), "HSEBYP": rcc.field(0x00, 18, 1),
        "PLL1ON": rcc.field(0x00, 24, 1), "PLLSRC": rcc.field(0x28, 0, 2),
        "DIVM1": rcc.field(0x28, 4, 6), "DIVN1": rcc.field(0x30, 0, 9) + 1,
        "DIVP1": rcc.field(0x30, 9, 7) + 1, "DIVQ1": rcc.field(0x30, 16, 7) + 1,
        "DIVP1EN": rcc.field(0x2C, 16, 1), "DIVQ1EN": rcc.field(0x2C, 17, 1),
        "SWS": rcc.field(0x10, 3, 3),
        "D1CPRE": ahb_div(rcc.field(0x18, 8, 4)), "HPRE": ahb_div(rcc.field(0x18, 0, 4)),
        "D1PPRE": apb_div(rcc.field(0x18, 4, 3)), "D2PPRE1": apb_div(rcc.field(0x1C, 4, 3)),
        "D2PPRE2": apb_div(rcc.field(0x1C, 8, 3)), "D3PPRE": apb_div(rcc.field(0x20, 4, 3)),
        "VOS": pwr.vos(syscfg),
    }
    clocks = rcc.clocks()
    want_latency = flash_wait_states(expect["vos"], expect["cpu_hz"] / 2)
    got["LATENCY"], got["WRHIGHFREQ"] = flash.latency()
    want = {
        "HSEON": 1, "HSEBYP": int(expect["bypass"]), "PLL1ON": 1, "PLLSRC": 2,
        "DIVM1": expect["divm"], "DIVN1": expect["divn"], "DIVP1": 2, "DIVQ1": 8,
        "DIVP1EN": 1, "DIVQ1EN": 1, "SWS": 3, "D1CPRE": 1, "HPRE": 2, "D1PPRE": 2,
        "D2PPRE1": 2, "D2PPRE2": 2, "D3PPRE": 2, "VOS": expect["vos"],
        "LATENCY": want_latency[0], "WRHIGHFREQ": want_latency[1],
    }
    problems = [f"{k} = {got[k]}, expected {v}" for k, v in want.items() if got[k] != v]
    ref, vco, p, q, _ = rcc.pll(1)
    if abs(clocks["cpu"] - expect["cpu_hz"]) > 1:
        problems.append(f"CPU clock {clocks['cpu'] / 1e6:.3f} MHz, "
                        f"expected {expect['cpu_hz'] / 1e6:.0f}")
    if not 1e6 <= ref <= 16e6:
        problems.append(f"PLL1 reference {ref / 1e6:.3f} MHz outside 1-16 MHz")
    summary = (f"HSE {rcc.hse_hz / 1e6:g} MHz{' bypass' if got['HSEBYP'] else ''} / M{got['DIVM1']}"
               f" = {ref / 1e6:g} MHz x N{got['DIVN1']} = VCO {vco / 1e6:g} MHz; P/{got['DIVP1']}"
               f" = CPU {clocks['cpu'] / 1e6:g} MHz, Q/{got['DIVQ1']} = {q / 1e6:g} MHz; "
               f"HCLK {clocks['hclk'] / 1e6:g} MHz, PCLK1-4 {clocks['pclk1'] / 1e6:g} MHz, "
               f"TIM2 {clocks['tim_apb1'] / 1e6:g} MHz; VOS{got['VOS']}; flash LATENCY "
               f"{got['LATENCY']} WRHIGHFREQ {got['WRHIGHFREQ']}")
    return problems, summary
