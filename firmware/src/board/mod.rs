//! The two supported boards: pin maps, clocks and the drivers built from them.
//!
//! Exactly one board feature is enabled (`board-nucleo`, the default, or `board-openmv`);
//! each also selects its chip for embassy-stm32 (`stm32h743zi`, LQFP144, on the NUCLEO;
//! `stm32h743vi`, LQFP100, on the OpenMV Cam H7), so a pin that does not exist on the chip
//! fails to compile. Each board module provides the same items:
//!
//! - `NAME`, `HSE` (the clock into OSC_IN and its PLL pre-divider, see [`crate::clocks`]) and
//!   `XCLK_HZ` (the camera clock driven out of MCO1);
//! - `init(p, baud, watchdog_timeout_us) -> Board`: claims the pins and builds every driver,
//!   written once here (`board_pins!`) and given each board's pin table.
//!
//! The wiring, with the module's labels, the sources of each pin and what was not checked
//! against the board, is in `firmware/README.md` ("Wiring").

#[cfg(all(feature = "board-nucleo", feature = "board-openmv"))]
compile_error!(
    "enable exactly one board feature: `board-openmv` needs `--no-default-features` \
     (the default is `board-nucleo`)"
);
#[cfg(not(any(feature = "board-nucleo", feature = "board-openmv")))]
compile_error!("enable one board feature: `board-nucleo` or `board-openmv`");

/// A board's pin table, and from it the bring-up every board shares: the interrupt bindings
/// (`Irqs`) and `init`. The peripherals are typed by their pins (a pin without the function
/// fails to compile), hence a macro rather than a function over the pins. The DMA streams
/// are the same on every board: DMA1 stream 0 for the DCMI, 1 and 2 for the SCCB.
macro_rules! board_pins {
    (
        led: $led:ident starting $led_level:ident,
        xclk: $xclk:ident = HSI48 / $xclk_div:ident,
        dcmi: [$d0:ident, $d1:ident, $d2:ident, $d3:ident, $d4:ident, $d5:ident, $d6:ident, $d7:ident],
        sync: vsync $vsync:ident, hsync $hsync:ident, pixclk $pixclk:ident,
        sccb: scl $scl:ident, sda $sda:ident,
        camera: reset $reset:ident, power_down $power_down:ident,
        uart: $uart:ident rx $rx:ident tx $tx:ident,
    ) => {
        use embassy_stm32::dcmi::{self, Dcmi};
        use embassy_stm32::flash::{self, Flash};
        use embassy_stm32::gpio::{Level, Output, Speed};
        use embassy_stm32::i2c::{self, I2c};
        use embassy_stm32::peripherals::{self, DCMI};
        use embassy_stm32::rcc::{Mco, Mco1Source, McoPrescaler};
        use embassy_stm32::usart::{self, BufferedUart};
        use embassy_stm32::wdg::IndependentWatchdog;
        use embassy_stm32::{bind_interrupts, dma, Peripherals};

        use super::{Board, CameraPins};
        use crate::capture::FrameStamp;

        bind_interrupts!(struct Irqs {
            DCMI => dcmi::InterruptHandler<DCMI>, FrameStamp;
            DMA1_STREAM0 => dma::InterruptHandler<peripherals::DMA1_CH0>;
            DMA1_STREAM1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
            DMA1_STREAM2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
            I2C1_EV => i2c::EventInterruptHandler<peripherals::I2C1>;
            I2C1_ER => i2c::ErrorInterruptHandler<peripherals::I2C1>;
            $uart => usart::BufferedInterruptHandler<peripherals::$uart>;
            FLASH => flash::InterruptHandler;
        });

        /// Claims the pins and builds the drivers; `baud` is the flight-controller UART's rate.
        pub fn init(p: Peripherals, baud: u32, watchdog_timeout_us: u32) -> Board {
            let led = Output::new(p.$led, Level::$led_level, Speed::Low);

            // XCLK first: the sensor's SCCB port needs its clock running.
            let xclk = Mco::new(
                p.MCO1,
                p.$xclk,
                Mco1Source::HSI48,
                super::xclk_config(McoPrescaler::$xclk_div),
            );

            let dcmi = Dcmi::new_8bit(
                p.DCMI,
                p.DMA1_CH0,
                Irqs,
                p.$d0,
                p.$d1,
                p.$d2,
                p.$d3,
                p.$d4,
                p.$d5,
                p.$d6,
                p.$d7,
                p.$vsync,
                p.$hsync,
                p.$pixclk,
                crate::capture::dcmi_config(),
            );
            let sccb = I2c::new(
                p.I2C1,
                p.$scl,
                p.$sda,
                p.DMA1_CH1,
                p.DMA1_CH2,
                Irqs,
                super::sccb_config(),
            );
            let camera = CameraPins {
                dcmi,
                sccb,
                reset_n: Output::new(p.$reset, Level::Low, Speed::Low),
                power_down: Output::new(p.$power_down, Level::High, Speed::Low),
                xclk,
            };

            let (tx_buffer, rx_buffer) = super::uart_buffers();
            let uart = defmt::unwrap!(BufferedUart::new(
                p.$uart,
                p.$rx,
                p.$tx,
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
    };
}

#[cfg(feature = "board-nucleo")]
mod nucleo;
#[cfg(feature = "board-nucleo")]
pub use nucleo::{init, HSE, NAME, XCLK_HZ};

#[cfg(feature = "board-openmv")]
mod openmv;
#[cfg(feature = "board-openmv")]
pub use openmv::{init, HSE, NAME, XCLK_HZ};

use embassy_stm32::dcmi::Dcmi;
use embassy_stm32::flash::{Async as FlashAsync, Flash};
use embassy_stm32::gpio::{Output, Speed};
use embassy_stm32::i2c::{self, I2c, Master};
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::{DCMI, IWDG1, MCO1};
use embassy_stm32::rcc::{Mco, McoConfig, McoPrescaler};
use embassy_stm32::time::Hertz;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;

/// The external clock into OSC_IN.
pub struct HseClock {
    /// Frequency, Hz.
    pub hz: u32,
    /// `true`: an oscillator drives OSC_IN (bypass mode); `false`: a crystal.
    pub bypass: bool,
    /// PLL1 input divider (DIVM) giving a 4 MHz reference.
    pub prediv: embassy_stm32::rcc::PllPreDiv,
}

/// The camera's hardware: the parallel bus, its control bus and its control pins.
pub struct CameraPins {
    /// DCMI with its DMA stream, 8 data lines, HSYNC, VSYNC, PIXCLK.
    pub dcmi: Dcmi<'static, DCMI>,
    /// SCCB (I2C1) to the sensor's registers.
    pub sccb: I2c<'static, Async, Master>,
    /// RESETB, active low: low holds the sensor in reset.
    pub reset_n: Output<'static>,
    /// PWDN, active high: high powers the sensor down.
    pub power_down: Output<'static>,
    /// XCLK from MCO1 (kept alive: dropping it would not stop the clock, but owning it
    /// documents that the pin is taken).
    pub xclk: Mco<'static, MCO1>,
}

/// Everything the tasks need, built from the board's pins.
pub struct Board {
    /// The heartbeat LED.
    pub led: Output<'static>,
    /// The camera.
    pub camera: CameraPins,
    /// The UART to the flight controller (interrupt driven, buffers in DTCM).
    pub uart: BufferedUart<'static>,
    /// The flash controller (parameter storage).
    pub flash: Flash<'static, FlashAsync>,
    /// The independent watchdog.
    pub watchdog: IndependentWatchdog<'static, IWDG1>,
}

/// Bytes of the UART's receive ring buffer: 22 ms of a saturated 921600-baud line, enough
/// to ride out the vision task's longest stretch without a yield (one detection).
pub const UART_RX_BUFFER: usize = 2048;
/// Bytes of the UART's transmit ring buffer.
pub const UART_TX_BUFFER: usize = 512;

/// MCO1 settings for the camera's XCLK: `prescaler` divides HSI48 down to the board's
/// `XCLK_HZ`; the fastest pin speed keeps the clock's edges clean at 12-24 MHz.
fn xclk_config(prescaler: McoPrescaler) -> McoConfig {
    let mut config = McoConfig::default();
    config.prescaler = prescaler;
    config.speed = Speed::VeryHigh;
    config
}

/// SCCB clock: 400 kHz, the maximum of the SCCB timing tables in both the OV7725 and the
/// OV2640 datasheets (fSIOC). Four times the old 100 kHz shortens an exposure update (three to
/// five register writes) from about 1.2 ms to 0.3 ms and the sensor set-up likewise. I2C fast
/// mode allows a 300 ns rise time: with the usual 4.7 kΩ pull-ups that is about 75 pF of bus,
/// plenty for a module on short wires (the OpenMV's sensor sits next to the MCU). A module
/// with weak (10 kΩ) pull-ups and long wires may need stronger pull-ups, or 100 kHz here.
/// embassy-stm32's I2C v2 derives the fast-mode timing from the I2C kernel clock (PCLK1, 100
/// or 120 MHz here): SCL low twice as long as high, 1.66 µs and 0.83 µs at 100 MHz, above
/// fast mode's 1.3 µs and 0.6 µs minimums.
pub const SCCB_HZ: u32 = 400_000;

/// I2C settings of the sensor's SCCB port ([`SCCB_HZ`]).
fn sccb_config() -> i2c::Config {
    let mut config = i2c::Config::default();
    config.frequency = Hertz(SCCB_HZ);
    config
}

/// UART settings of the flight-controller link (8N1 at `baud`).
fn uart_config(baud: u32) -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = baud;
    config
}

/// The UART ring buffers, claimed once (statics in DTCM: the UART is interrupt driven, the
/// CPU copies every byte, so no DMA needs to reach them).
fn uart_buffers() -> (&'static mut [u8], &'static mut [u8]) {
    let tx = defmt::unwrap!(cortex_m::singleton!(: [u8; UART_TX_BUFFER] = [0; UART_TX_BUFFER]));
    let rx = defmt::unwrap!(cortex_m::singleton!(: [u8; UART_RX_BUFFER] = [0; UART_RX_BUFFER]));
    (tx, rx)
}
