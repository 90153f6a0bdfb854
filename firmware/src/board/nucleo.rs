//! NUCLEO-H743ZI2 (STM32H743ZI, LQFP144) with an OV7725 or OV2640 module wired to the DCMI
//! pins (alternate functions checked against embassy's `stm32-metapac` pin data; the wiring,
//! with the module's labels and the board's caveats, is in `firmware/README.md`).
//!
//! Clock: the ST-LINK's 8 MHz MCO into OSC_IN (HSE bypass). Camera clock: HSI48 / 2 =
//! 24 MHz on MCO1.

use embassy_stm32::rcc::PllPreDiv;

use super::HseClock;

/// Board name for the log.
pub const NAME: &str = "NUCLEO-H743ZI2";
/// 8 MHz from the ST-LINK's MCO, an oscillator (bypass); 8 / 2 = 4 MHz PLL reference.
pub const HSE: HseClock = HseClock {
    hz: 8_000_000,
    bypass: true,
    prediv: PllPreDiv::DIV2,
};
/// Camera clock: HSI48 / 2.
pub const XCLK_HZ: u32 = 24_000_000;

board_pins! {
    // LD1, green.
    led: PB0 starting Low,
    xclk: PA8 = HSI48 / DIV2,
    dcmi: [PC6, PC7, PE0, PC9, PE4, PB6, PE5, PE6],
    sync: vsync PB7, hsync PA4, pixclk PA6,
    sccb: scl PB8, sda PB9,
    camera: reset PD4, power_down PD7,
    // TX PG14 to the flight controller's RX, RX PG9 from its TX.
    uart: USART6 rx PG9 tx PG14,
}
