//! Clock tree and core voltage.
//!
//! Source: the board's HSE ([`crate::board::HSE`]). The NUCLEO-H743ZI2 feeds OSC_IN (PH0)
//! with the 8 MHz MCO output of its ST-LINK (no crystal fitted by default), so HSE runs in
//! *bypass* mode at 8 MHz, divided by 2; the OpenMV Cam H7 has a 12 MHz crystal, divided by
//! 3. Either way PLL1 sees a 4 MHz reference and everything below is the same.
//!
//! | clock | default (400 MHz) | feature `clk-480mhz` |
//! |---|---|---|
//! | voltage scale | VOS1 | VOS0 |
//! | PLL1 reference = HSE / DIVM | 4 MHz | 4 MHz |
//! | PLL1 VCO = ref x DIVN | 4 x 200 = 800 MHz | 4 x 240 = 960 MHz |
//! | SYSCLK = CPU = PLL1_P = VCO / 2 | 400 MHz | 480 MHz |
//! | PLL1_Q = VCO / 8 (SPI1-3, SDMMC kernel clock) | 100 MHz | 120 MHz |
//! | HCLK (AXI, AHB, AXI SRAM) = SYSCLK / 2 | 200 MHz | 240 MHz |
//! | PCLK1-4 (APB: USARTs, TIM2 time driver) = HCLK / 2 | 100 MHz | 120 MHz |
//!
//! Why 400 MHz by default: it is the fastest setting every STM32H743 silicon revision supports
//! (revision Y tops out at 400 MHz in VOS1; only revision V reaches 480 MHz, and only in VOS0,
//! the highest core voltage). VOS1 also runs cooler, which matters in a closed camera housing
//! under a summer sun, and the detector's QVGA budget does not need the extra 20 %. Boards with
//! revision V silicon (every NUCLEO-H743ZI2) can enable the `clk-480mhz` feature; embassy then
//! programs VOS0 (and checks every bus clock against the VOS0 limits at start-up).
//!
//! Everything here goes through embassy-stm32's typed `rcc::Config`; no register is touched
//! directly. embassy also sets the flash wait states for the chosen AXI clock and voltage.

use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllDiv, PllMul, PllSource, Sysclk, VoltageScale,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::Config;

use crate::board::HSE;

/// Core clock this build runs at.
#[cfg(not(feature = "clk-480mhz"))]
pub const CPU_HZ: u32 = 400_000_000;
/// Core clock this build runs at.
#[cfg(feature = "clk-480mhz")]
pub const CPU_HZ: u32 = 480_000_000;

#[cfg(not(feature = "clk-480mhz"))]
const PLL1_MUL: PllMul = PllMul::MUL200;
#[cfg(feature = "clk-480mhz")]
const PLL1_MUL: PllMul = PllMul::MUL240;

#[cfg(not(feature = "clk-480mhz"))]
const VOLTAGE_SCALE: VoltageScale = VoltageScale::Scale1;
#[cfg(feature = "clk-480mhz")]
const VOLTAGE_SCALE: VoltageScale = VoltageScale::Scale0;

/// embassy configuration: the clock tree above, everything else at embassy's defaults.
pub fn config() -> Config {
    let mut config = Config::default();
    let rcc = &mut config.rcc;
    rcc.hse = Some(Hse {
        freq: Hertz(HSE.hz),
        mode: if HSE.bypass {
            HseMode::Bypass
        } else {
            HseMode::Oscillator
        },
    });
    rcc.pll1 = Some(Pll {
        source: PllSource::HSE,
        prediv: HSE.prediv,
        mul: PLL1_MUL,
        fracn: None,
        divp: Some(PllDiv::DIV2),
        divq: Some(PllDiv::DIV8),
        divr: None,
    });
    rcc.sys = Sysclk::PLL1_P;
    rcc.d1c_pre = AHBPrescaler::DIV1;
    rcc.ahb_pre = AHBPrescaler::DIV2;
    rcc.apb1_pre = APBPrescaler::DIV2;
    rcc.apb2_pre = APBPrescaler::DIV2;
    rcc.apb3_pre = APBPrescaler::DIV2;
    rcc.apb4_pre = APBPrescaler::DIV2;
    rcc.voltage_scale = VOLTAGE_SCALE;
    config
}
