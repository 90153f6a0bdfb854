//! OpenMV Cam H7 (STM32H743VI, LQFP100) with its on-board OV7725. The camera wiring is fixed
//! on the board: taken from OpenMV's published board configuration for this camera,
//! alternate functions checked against embassy's `stm32-metapac` pin data (the wiring is in
//! `firmware/README.md`).
//!
//! Clock: a 12 MHz crystal on OSC_IN (OpenMV's PLL settings divide it by 3 for a 4 MHz
//! reference). Camera clock: HSI48 / 4 = 12 MHz on MCO1 (OpenMV drives the same pin from TIM1
//! at 12 MHz; MCO1 is the other function of PA8).

use embassy_stm32::rcc::PllPreDiv;

use super::HseClock;

/// Board name for the log.
pub const NAME: &str = "OpenMV Cam H7";
/// 12 MHz crystal; 12 / 3 = 4 MHz PLL reference.
pub const HSE: HseClock = HseClock {
    hz: 12_000_000,
    bypass: false,
    prediv: PllPreDiv::DIV3,
};
/// Camera clock: HSI48 / 4 (what OpenMV's own firmware runs this sensor at).
pub const XCLK_HZ: u32 = 12_000_000;

board_pins! {
    // The green LED, active low: starts dark.
    led: PC1 starting High,
    xclk: PA8 = HSI48 / DIV4,
    dcmi: [PC6, PC7, PE0, PE1, PE4, PB6, PE5, PE6],
    sync: vsync PB7, hsync PA4, pixclk PA6,
    sccb: scl PB8, sda PB9,
    camera: reset PA10, power_down PD7,
    // TX PB10 (P4) to the flight controller's RX, RX PB11 (P5) from its TX.
    uart: USART3 rx PB11 tx PB10,
}
