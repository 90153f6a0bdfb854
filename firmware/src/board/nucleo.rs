//! NUCLEO-H743ZI2 (STM32H743ZI, LQFP144) with an OV7725 or OV2640 module wired to the DCMI pins.
//!
//! Pin map (alternate functions checked against embassy's `stm32-metapac` pin data; the
//! wiring table with the module's labels is in `firmware/README.md`):
//!
//! | signal | pin | | signal | pin |
//! |---|---|---|---|---|
//! | DCMI_D0 | PC6 | | DCMI_PIXCLK | PA6 |
//! | DCMI_D1 | PC7 | | DCMI_HSYNC | PA4 |
//! | DCMI_D2 | PE0 | | DCMI_VSYNC | PB7 |
//! | DCMI_D3 | PC9 | | SCCB SCL (I2C1) | PB8 |
//! | DCMI_D4 | PE4 | | SCCB SDA (I2C1) | PB9 |
//! | DCMI_D5 | PB6 | | XCLK (MCO1) | PA8 |
//! | DCMI_D6 | PE5 | | camera RESETB | PD4 |
//! | DCMI_D7 | PE6 | | camera PWDN | PD7 |
//! | USART6_TX (to FC RX) | PG14 | | USART6_RX (from FC TX) | PG9 |
//! | LED LD1 (green) | PB0 | | | |
//!
//! Clock: the ST-LINK's 8 MHz MCO into OSC_IN (HSE bypass). Camera clock: HSI48 / 2 =
//! 24 MHz on MCO1.

use embassy_stm32::dcmi::{self, Dcmi};
use embassy_stm32::flash::{self, Flash};
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::i2c::{self, I2c};
use embassy_stm32::peripherals::{self, DCMI};
use embassy_stm32::rcc::{Mco, Mco1Source, McoPrescaler, PllPreDiv};
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, Peripherals};

use super::{Board, CameraPins, HseClock};
use crate::capture::FrameStamp;

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

bind_interrupts!(struct Irqs {
    DCMI => dcmi::InterruptHandler<DCMI>, FrameStamp;
    DMA1_STREAM0 => dma::InterruptHandler<peripherals::DMA1_CH0>;
    DMA1_STREAM1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
    DMA1_STREAM2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
    I2C1_EV => i2c::EventInterruptHandler<peripherals::I2C1>;
    I2C1_ER => i2c::ErrorInterruptHandler<peripherals::I2C1>;
    USART6 => usart::BufferedInterruptHandler<peripherals::USART6>;
    FLASH => flash::InterruptHandler;
});

/// Claims the pins and builds the drivers; `baud` is the flight-controller UART's rate.
pub fn init(p: Peripherals, baud: u32, watchdog_timeout_us: u32) -> Board {
    let led = Output::new(p.PB0, Level::Low, Speed::Low);

    // XCLK first: the sensor's SCCB port needs its clock running.
    let xclk = Mco::new(
        p.MCO1,
        p.PA8,
        Mco1Source::HSI48,
        super::xclk_config(McoPrescaler::DIV2),
    );

    let dcmi = Dcmi::new_8bit(
        p.DCMI,
        p.DMA1_CH0,
        Irqs,
        p.PC6,
        p.PC7,
        p.PE0,
        p.PC9,
        p.PE4,
        p.PB6,
        p.PE5,
        p.PE6,
        p.PB7,
        p.PA4,
        p.PA6,
        crate::capture::dcmi_config(),
    );
    let sccb = I2c::new(
        p.I2C1,
        p.PB8,
        p.PB9,
        p.DMA1_CH1,
        p.DMA1_CH2,
        Irqs,
        super::sccb_config(),
    );
    let camera = CameraPins {
        dcmi,
        sccb,
        reset_n: Output::new(p.PD4, Level::Low, Speed::Low),
        power_down: Output::new(p.PD7, Level::High, Speed::Low),
        xclk,
    };

    let (tx_buffer, rx_buffer) = super::uart_buffers();
    let uart = defmt::unwrap!(BufferedUart::new(
        p.USART6,
        p.PG9,
        p.PG14,
        tx_buffer,
        rx_buffer,
        Irqs,
        super::uart_config(baud)
    ));

    Board {
        led,
        camera,
        uart,
        flash: Flash::new(p.FLASH, Irqs),
        watchdog: IndependentWatchdog::new(p.IWDG1, watchdog_timeout_us),
    }
}
