//! OmniVision OV2640: 2-megapixel (UXGA, 1600x1200) CMOS sensor with an on-chip DSP,
//! configured over SCCB.
//!
//! The OV2640 has two register banks behind one SCCB address: the *sensor* bank (array
//! timing, window, clock, exposure, gain) and the *DSP* bank (colour processing, scaling,
//! output format). Register 0xFF selects the bank every other access goes to. The driver
//! remembers the selected bank and only writes 0xFF when the next access needs the other one;
//! it selects again regardless after the register reset, at every id check (the sensor may
//! have been reset through its pins since) and after a bank select that failed.
//!
//! What this driver sets up, and nothing else (every register not named here or in the
//! [`table`]s keeps its reset value):
//!
//! - **Identity**: PIDH/PIDL must read `0x26`/`0x40..=0x42` and MIDH/MIDL `0x7F`/`0xA2`
//!   before anything but the bank select is written, so a wrong device is an error, not a
//!   device we scribble on.
//! - **Reset**: COM7 bit 7 in the sensor bank puts every register back to its default
//!   ([`RESET_SETTLE_US`]).
//! - **OmniVision's reference set-up** ([`table`]): the sensor's reserved analog and readout
//!   registers, the tuning of its own AEC, the SVGA mode's analog timing and the DSP's
//!   colour-processing block (pixel correction, gamma, white balance, colour matrix), with
//!   the values every working OV2640 driver writes. Most of these registers are marked
//!   reserved in the datasheet and their meaning is not published; left at their power-up
//!   values the sensor is not in the state any of those drivers run it in, and the image is
//!   likely unusable. The tables leave out every register this driver derives itself (the
//!   items below), so nothing in them can undo the mode, the window, the clock plan, the
//!   scaling, the format, the sync polarity or the exposure mode.
//! - **Sensor window: SVGA.** COM7 selects the 800x600 mode, which reads the whole
//!   1600x1200 array subsampled by two in each direction: the full field of view, at up to
//!   30 fps, with a 600-line readout. The UXGA mode reads all 1200 lines, so it tops out at
//!   15 fps and its rolling shutter skews the image over twice as long, which is worse for a
//!   camera on a moving drone than the resolution it adds is better (QVGA and VGA are smaller
//!   than SVGA either way). The window registers (HREFST/HREFEND/REG32, VSTRT/VEND/COM1)
//!   span 800x600 ([`SVGA_WINDOW`]).
//! - **Scaling to QVGA or VGA** in the DSP: the DSP is told its input is 800x600
//!   (HSIZE8/VSIZE8, HSIZE/VSIZE), QVGA first halves it (CTRLI down-sampling, to 400x300),
//!   and the zoom stage (ZMOW/ZMOH) scales by 0.8 to 320x240 or 640x480. Both are 4:3 like
//!   the window, so nothing is cropped and pixels stay square.
//! - **Format**: YUV 4:2:2 with Y first (`Y0 U0 Y1 V0 ...`): IMAGE_MODE selects YUV 4:2:2
//!   with its byte-swap bit 0 clear (high byte, Y, first) and CTRL0's V-first bit clear
//!   (U before V), plus the DSP output settings OmniVision pairs with that byte order
//!   ([`table::YUV422`]). The camera interface keeps every first byte of a pair: 8-bit grey.
//! - **Frame rate**: the sensor clock is `XCLK x (2 if CLKRC's doubler) / (CLKRC[5:0] + 1)`,
//!   one SVGA line is 1190 sensor clocks and one frame 672 lines (OmniVision's frame-rate
//!   note for the SVGA mode: 24 MHz gives 30.01 fps; the SVGA banding steps in
//!   [`table::SVGA_TIMING`], 202 lines per 10 ms, say the same); [`plan_clock`] picks the
//!   doubler and divider and adds dummy lines (FLL/FLH) to hit the requested rate. The
//!   output pixel clock is set by hand (R_DVP_SP, automatic mode off), so it is the one
//!   [`FrameTiming::pclk_hz`](crate::FrameTiming::pclk_hz) reports.
//! - **Sync signals**: VSYNC is inverted (COM10 bit 1) so it is high between frames like the
//!   OV7725's; HREF (high during a line's data) and PCLK (data changes on the falling edge)
//!   stay as reset. One camera interface set-up then serves both sensors (see
//!   [`crate::any`]).
//! - **Exposure and gain**: the sensor's own AEC/AGC with a gain ceiling (COM8, COM9), or
//!   manual exposure (16 bits of line periods split over REG45, AEC and REG04) and gain
//!   (GAIN). With a hard exposure limit, run
//!   [`touchdown_core::sensor::AutoExposure`] and feed its manual settings here.
//!   The banding filter stays off in both.
//!
//! The whole set-up is data: the tables and the values derived here are lists of
//! [`Setting`]s that one loop writes ([`Ov2640::init`]), so the firmware carries one copy of
//! the register-write code instead of one per register. A write that fails stops the set-up
//! with [`Error::Write`], which names the bank and register.
//!
//! The bus is SCCB: a register read is a write of the register address, a STOP, then a
//! separate one-byte read ([`Ov2640::read_register`]), never `write_read`.
//!
//! Sources for the register semantics: the OV2640 datasheet's register tables (sensor bank:
//! GAIN, COM1, REG04, COM2, AEC, CLKRC, COM7..COM10, window, AEW/AEB/VV, REG32, REG45,
//! FLL/FLH, COM25, BD50/BD60, PIDH/PIDL, MIDH/MIDL; DSP bank: R_BYPASS, CTRLI, size and zoom
//! registers, CTRL0/CTRL2/CTRL3, R_DVP_SP, IMAGE_MODE, RESET, MC_BIST), OmniVision's
//! software application notes (SVGA frame timing, dummy lines) and the bit definitions
//! documented in the Linux `ov2640` driver. The derived values are computed here. The values
//! in [`table`] are OmniVision's reference settings as three open drivers carry them (Linux
//! `drivers/media/i2c/ov2640.c`, OpenMV `drivers/sensors/ov2640.c`, esp32-camera
//! `sensors/private_include/ov2640_settings.h`); each table says which one it follows where
//! they differ.
//!
//! The driver is split by concern: [`reg`] is the register map of both banks, [`table`] the
//! vendor's reference values, `setup` the register values this driver derives from the
//! configuration (mode, window, scaling, format, clock, orientation), `clock` the clock plan
//! for a frame rate ([`plan_clock`]). This module holds the driver that writes them in order,
//! and the register field values the derived set-up, the clock plan and the driver share.

use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;

use crate::ov7725::{gain_from_register, gain_register};
use crate::{gain_ceiling_log2, Config, ConfigError, Exposure, GainX16, Resolution};

mod clock;
pub mod reg;
mod setup;
pub mod table;

pub use clock::{plan_clock, ClockPlan};
use setup::{
    clock_and_sync, dsp_start, orientation, BYPASS_DSP, DSP_QVGA, DSP_VGA, MODE_AND_WINDOW,
};

/// 7-bit SCCB address (0x60 to write, 0x61 to read in 8-bit notation).
pub const I2C_ADDRESS: u8 = 0x30;
/// Product id, high byte (PIDH).
pub const PRODUCT_ID_HIGH: u8 = 0x26;
/// Product id, low byte (PIDL): silicon revisions read 0x40, 0x41 or 0x42.
pub const PRODUCT_ID_LOW: core::ops::RangeInclusive<u8> = 0x40..=0x42;
/// Manufacturer id (MIDH, MIDL): OmniVision.
pub const MANUFACTURER_ID: u16 = 0x7FA2;
/// Wait after the register reset before the next access, µs. The datasheet gives no figure
/// for the software reset; 10 ms leaves a wide margin over the few milliseconds the sensor
/// takes to answer again.
pub const RESET_SETTLE_US: u32 = 10_000;
/// Input clock range of the sensor (datasheet key specifications), Hz.
pub const XCLK_RANGE_HZ: core::ops::RangeInclusive<u32> = 6_000_000..=36_000_000;
/// Highest sensor clock [`plan_clock`] uses, Hz: OmniVision's rating of the SVGA mode is
/// 30 fps, which is exactly this clock (1190 x 672 clocks per frame).
pub const MAX_SENSOR_CLOCK_HZ: u32 = 24_000_000;
/// A frame rate within this many parts per million of the request counts as exact.
pub const FPS_TOLERANCE_PPM: u64 = 5_000;

/// Sensor clocks per line in the SVGA mode, no dummy pixels (OmniVision's frame-rate note).
pub const SVGA_LINE_CLOCKS: u32 = 1190;
/// Lines per frame in the SVGA mode, no dummy lines.
pub const SVGA_FRAME_LINES: u32 = 672;
/// Image lines read out per SVGA frame.
pub const SVGA_ACTIVE_LINES: u32 = 600;
/// Width of the SVGA image the DSP receives.
pub const SVGA_WIDTH: u16 = 800;
/// Height of the SVGA image the DSP receives.
pub const SVGA_HEIGHT: u16 = 600;

/// The register banks, as written to [`reg::BANK_SEL`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Bank {
    /// The DSP bank (0): image processing, scaling, output format.
    Dsp = 0,
    /// The sensor bank (1): array timing, window, clock, exposure and gain.
    Sensor = 1,
}

/// COM7 bit 7: reset every register to its default.
const COM7_RESET: u8 = 0x80;
/// COM7 bits \[6:4\] = 100: the SVGA mode (zoom and colour bar off).
const COM7_SVGA: u8 = 0x40;
/// REG04 bit 7: horizontal mirror.
const REG04_MIRROR: u8 = 0x80;
/// REG04 bit 6: vertical flip.
const REG04_VFLIP: u8 = 0x40;
/// REG04 bit 5: reserved, written 1 as in OmniVision's settings.
const REG04_RESERVED: u8 = 0x20;
/// REG04 bit 4: vertical window start bit 0. Set with the vertical flip: the flipped readout
/// then starts one row later, on the same Bayer colour row as the unflipped one, so the
/// DSP's colour interpolation (and with it Y) stays right.
const REG04_VREF0: u8 = 0x10;
/// REG04 bit 3: horizontal window start bit 0, set as in OmniVision's settings (the Bayer
/// phase of the unflipped readout).
const REG04_HREF0: u8 = 0x08;
/// REG04 bits \[1:0\]: exposure AEC\[1:0\].
const REG04_AEC_MASK: u8 = 0x03;
/// CLKRC bit 7: clock doubler.
const CLKRC_DOUBLER: u8 = 0x80;
/// Largest CLKRC divider field value (6 bits).
const CLKRC_MAX_DIVIDER: u8 = 63;
/// COM10 bit 1: VSYNC negative, i.e. high between frames and low during them, as the
/// OV7725's VSYNC at its reset default.
const COM10_VSYNC_NEGATIVE: u8 = 0x02;
/// COM8 bits \[7:6\]: reserved, written 1 as in OmniVision's settings.
const COM8_RESERVED: u8 = 0xC0;
/// COM8 bit 2: AGC.
const COM8_AGC: u8 = 0x04;
/// COM8 bit 0: AEC.
const COM8_AEC: u8 = 0x01;
/// COM8 with the sensor's AEC and AGC on and the banding filter (bit 5) off: it would hold
/// the exposure at multiples of 1/100 s, far too long outdoors.
const COM8_AUTO: u8 = COM8_RESERVED | COM8_AGC | COM8_AEC;
/// COM8 for manual exposure and gain: AEC and AGC off.
const COM8_MANUAL: u8 = COM8_RESERVED;
/// COM9 bits \[7:5\]: gain ceiling field.
const COM9_CEILING_MASK: u8 = 0xE0;
/// REG45 bits \[5:0\]: exposure AEC\[15:10\]; bits \[7:6\] (AGC\[9:8\]) are written 0.
const REG45_AEC_MASK: u8 = 0x3F;

/// R_BYPASS bit 0: bypass the DSP.
const R_BYPASS_BYPASS: u8 = 0x01;
/// R_BYPASS = 0: use the DSP.
const R_BYPASS_USE_DSP: u8 = 0x00;
/// RESET bit 2: hold the output port (DVP) in reset.
const RESET_DVP: u8 = 0x04;
/// CTRLI bit 7 (LP_DP).
const CTRLI_LP_DP: u8 = 0x80;
/// CTRL2: down-sampling (bit 5), special digital effects (bit 4, neutral at reset), UV
/// adjust (bit 3), UV average (bit 2), colour matrix (bit 0: it forms Y from RGB). Every
/// OmniVision setting for a scaled YUV output enables exactly these.
const CTRL2_YUV_SCALED: u8 = 0x20 | 0x10 | 0x08 | 0x04 | 0x01;
/// CTRL0 bit 4: V before U.
const CTRL0_V_FIRST: u8 = 0x10;
/// CTRL0 bits 3, 2, 1: YUV 4:2:2, YUV output, RGB path (the colour matrix works on it).
const CTRL0_YUV422: u8 = 0x08 | 0x04 | 0x02;
/// CTRL0 bit 0: raw output.
const CTRL0_RAW: u8 = 0x01;
/// IMAGE_MODE = 0: YUV 4:2:2, byte swap off (high byte first: `Y U Y V`), no JPEG, not
/// Y-only (the camera interface's byte select does that, as for the OV7725).
const IMAGE_MODE_YUV422_Y_FIRST: u8 = 0x00;

/// The SVGA sensor window in the window registers' units (two pixels, two lines):
/// (horizontal start, width, vertical start, height). 400 x 300 units are the 800x600 the
/// DSP is told it receives; the start offsets are OmniVision's for the SVGA mode (column
/// unit 137, row unit 2), which skip the array's border.
pub const SVGA_WINDOW: (u16, u16, u16, u16) = (137, 400, 2, 300);

/// One register write of the set-up: the bank, the register in it, the value.
///
/// The set-up is a list of these ([`table`] and the values derived here), written in order by
/// one loop that selects the bank only when it changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Setting {
    /// The bank the register is in.
    pub bank: Bank,
    /// The register address in that bank (never [`reg::BANK_SEL`]: the driver selects banks).
    pub register: u8,
    /// The value written.
    pub value: u8,
}

impl Setting {
    /// A write to the sensor bank.
    pub const fn sensor(register: u8, value: u8) -> Self {
        Setting {
            bank: Bank::Sensor,
            register,
            value,
        }
    }

    /// A write to the DSP bank.
    pub const fn dsp(register: u8, value: u8) -> Self {
        Setting {
            bank: Bank::Dsp,
            register,
            value,
        }
    }
}

/// Why the sensor could not be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// A register read failed (no device, NACK, bus fault): the id check, or the read of a
    /// read-modify-write.
    Bus(E),
    /// A register write failed (NACK, bus fault): the bank and register it was for
    /// ([`reg::BANK_SEL`] for a failed bank select) and the bus error. The writes before it
    /// went through, so the sensor is half set up: run [`Ov2640::init`] again.
    Write {
        /// The bank of the register.
        bank: Bank,
        /// The register.
        register: u8,
        /// The bus error.
        error: E,
    },
    /// Something answered, but it is not an OV2640 (the ids as read).
    WrongChip {
        /// PIDH as read.
        pid: u8,
        /// PIDL as read.
        ver: u8,
        /// MIDH:MIDL as read.
        manufacturer: u16,
    },
    /// The configuration cannot be realised.
    Config(ConfigError),
}

/// The identification registers as read ([`Ov2640::read_id`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChipId {
    /// PIDH.
    pub pid: u8,
    /// PIDL.
    pub ver: u8,
    /// MIDH:MIDL.
    pub manufacturer: u16,
}

impl ChipId {
    /// Whether these are an OV2640's ids ([`PRODUCT_ID_HIGH`], [`PRODUCT_ID_LOW`],
    /// [`MANUFACTURER_ID`]).
    pub fn is_ov2640(&self) -> bool {
        self.pid == PRODUCT_ID_HIGH
            && PRODUCT_ID_LOW.contains(&self.ver)
            && self.manufacturer == MANUFACTURER_ID
    }
}

/// Splits a 16-bit exposure (line periods) into its registers: (REG45\[5:0\] = AEC\[15:10\],
/// AEC = AEC\[9:2\], REG04\[1:0\] = AEC\[1:0\]).
pub const fn exposure_fields(lines: u16) -> (u8, u8, u8) {
    (
        ((lines >> 10) as u8) & REG45_AEC_MASK,
        (lines >> 2) as u8,
        (lines as u8) & REG04_AEC_MASK,
    )
}

/// Joins the exposure registers (REG45, AEC, REG04 as read) into line periods.
pub const fn exposure_from_fields(reg45: u8, aec: u8, reg04: u8) -> u16 {
    (((reg45 & REG45_AEC_MASK) as u16) << 10)
        | ((aec as u16) << 2)
        | ((reg04 & REG04_AEC_MASK) as u16)
}

/// The OV2640 on an SCCB (I2C) bus.
#[derive(Debug)]
pub struct Ov2640<I> {
    i2c: I,
    /// The bank the sensor has selected, if known.
    bank: Option<Bank>,
    /// REG04 without the exposure bits (flip, mirror, window LSBs), so a manual exposure
    /// update writes REG04 without reading it first.
    reg04: u8,
    /// Longest exposure the frame allows (the sensor caps the exposure at one frame), lines.
    max_exposure_lines: u16,
}

impl<I: I2c> Ov2640<I> {
    /// A driver for the sensor at [`I2C_ADDRESS`] on `i2c`. Nothing is sent yet.
    pub fn new(i2c: I) -> Self {
        Ov2640 {
            i2c,
            bank: None,
            reg04: REG04_RESERVED | REG04_HREF0,
            max_exposure_lines: u16::MAX,
        }
    }

    /// Gives the bus back.
    pub fn release(self) -> I {
        self.i2c
    }

    /// The longest manual exposure [`Ov2640::set_manual`] writes, line periods: the frame
    /// length after [`Ov2640::init`], the register's range before.
    pub fn max_exposure_lines(&self) -> u16 {
        self.max_exposure_lines
    }

    /// Selects `bank` unless it is known to be selected already.
    async fn select_bank(&mut self, bank: Bank) -> Result<(), I::Error> {
        if self.bank == Some(bank) {
            return Ok(());
        }
        // Unknown until the write is known to have landed.
        self.bank = None;
        self.i2c
            .write(I2C_ADDRESS, &[reg::BANK_SEL, bank as u8])
            .await?;
        self.bank = Some(bank);
        Ok(())
    }

    /// Reads one register of `bank`: the address in one write transaction, STOP, then a
    /// one-byte read (SCCB has no repeated start).
    pub async fn read_register(&mut self, bank: Bank, register: u8) -> Result<u8, Error<I::Error>> {
        self.read_raw(bank, register).await.map_err(Error::Bus)
    }

    /// [`Ov2640::read_register`] with the bus's own error.
    async fn read_raw(&mut self, bank: Bank, register: u8) -> Result<u8, I::Error> {
        self.select_bank(bank).await?;
        self.i2c.write(I2C_ADDRESS, &[register]).await?;
        let mut value = [0u8];
        self.i2c.read(I2C_ADDRESS, &mut value).await?;
        let [value] = value;
        Ok(value)
    }

    /// Writes one register of `bank`. (To switch banks, pass the bank; a direct write of
    /// [`reg::BANK_SEL`] goes through, and the driver then re-selects before the next access.)
    /// A failure is [`Error::Write`] naming the register, or [`reg::BANK_SEL`] if the bank
    /// select before it failed.
    pub async fn write_register(
        &mut self,
        bank: Bank,
        register: u8,
        value: u8,
    ) -> Result<(), Error<I::Error>> {
        self.select_bank(bank).await.map_err(|error| Error::Write {
            bank,
            register: reg::BANK_SEL,
            error,
        })?;
        let result = self
            .i2c
            .write(I2C_ADDRESS, &[register, value])
            .await
            .map_err(|error| Error::Write {
                bank,
                register,
                error,
            });
        if register == reg::BANK_SEL {
            // The caller switched banks behind the driver's back: forget which is selected.
            self.bank = None;
        }
        result
    }

    /// Writes every [`Setting`] of every part, in order, stopping at the first failure.
    ///
    /// Every multi-register write of the driver goes through here: one loop, one await, so
    /// the register-write code exists once in the firmware instead of once per register.
    async fn write_settings(&mut self, parts: &[&[Setting]]) -> Result<(), Error<I::Error>> {
        for part in parts {
            for setting in *part {
                self.write_register(setting.bank, setting.register, setting.value)
                    .await?;
            }
        }
        Ok(())
    }

    /// Reads PIDH/PIDL and MIDH/MIDL (sensor bank). The bank select before the reads is the
    /// only write; it is always sent, because the sensor may have been reset or power-cycled
    /// through its pins since the driver last selected a bank.
    pub async fn read_id(&mut self) -> Result<ChipId, I::Error> {
        use reg::sensor::{MIDH, MIDL, PIDH, PIDL};
        self.bank = None;
        let mut id = [0u8; 4];
        for (value, register) in id.iter_mut().zip([PIDH, PIDL, MIDH, MIDL]) {
            *value = self.read_raw(Bank::Sensor, register).await?;
        }
        let [pid, ver, midh, midl] = id;
        Ok(ChipId {
            pid,
            ver,
            manufacturer: u16::from_be_bytes([midh, midl]),
        })
    }

    /// Reads the ids ([`Ov2640::read_id`]) and checks that they say OV2640.
    pub async fn check_id(&mut self) -> Result<(), Error<I::Error>> {
        let id = self.read_id().await.map_err(Error::Bus)?;
        if id.is_ov2640() {
            Ok(())
        } else {
            Err(Error::WrongChip {
                pid: id.pid,
                ver: id.ver,
                manufacturer: id.manufacturer,
            })
        }
    }

    /// Checks the id, resets the sensor and configures it. Returns the clock plan in force.
    /// The configuration is validated before anything is sent.
    ///
    /// The order of the writes after the reset, each part a list of [`Setting`]s:
    ///
    /// 1. [`table::DSP_PRELUDE`], [`table::SENSOR_COMMON`], [`table::DSP_COMMON`]: the
    ///    vendor's common set-up.
    /// 2. The DSP in bypass, COM7 = SVGA and the window, [`table::SVGA_TIMING`] (after the
    ///    mode select, as the reference that runs this mode writes it).
    /// 3. The derived sensor values: CLKRC and the frame length from [`plan_clock`], COM10,
    ///    REG04.
    /// 4. The derived DSP values: sizes, scaling, PCLK divider, IMAGE_MODE; then
    ///    [`table::YUV422`]; then CTRL0 (read, modified, written), the output port out of
    ///    reset and the DSP back in the path.
    /// 5. The exposure mode ([`Ov2640::set_exposure`]): COM8 (and COM9) last, so the
    ///    sensor's AEC/AGC are in the mode asked for whatever came before.
    ///
    /// No table holds a register of parts 2-5 (but the DSP's RESET, released in part 4), so
    /// every derived value is the last written to its register.
    pub async fn init<D: DelayNs>(
        &mut self,
        delay: &mut D,
        config: &Config,
    ) -> Result<ClockPlan, Error<I::Error>> {
        let plan =
            plan_clock(config.xclk_hz, config.resolution, config.fps).map_err(Error::Config)?;
        if let Exposure::Manual { lines: 0, .. } = config.exposure {
            return Err(Error::Config(ConfigError::ZeroExposure));
        }
        self.check_id().await?;

        // Every register back to its default, then give the sensor time to come back. The
        // reset may or may not reset the bank select as well: select again before the next
        // access.
        self.write_register(Bank::Sensor, reg::sensor::COM7, COM7_RESET)
            .await?;
        self.bank = None;
        delay.delay_us(RESET_SETTLE_US).await;

        self.reg04 = orientation(config);
        let clock = clock_and_sync(&plan, self.reg04);
        let dsp: &[Setting] = match config.resolution {
            Resolution::Qvga => &DSP_QVGA,
            Resolution::Vga => &DSP_VGA,
        };
        self.write_settings(&[
            table::DSP_PRELUDE,
            table::SENSOR_COMMON,
            table::DSP_COMMON,
            &BYPASS_DSP,
            &MODE_AND_WINDOW,
            table::SVGA_TIMING,
            &clock,
            dsp,
            table::YUV422,
        ])
        .await?;
        // CTRL0's AEC statistics bits [7:5] are kept as the sensor has them.
        let ctrl0 = self.read_register(Bank::Dsp, reg::dsp::CTRL0).await?;
        self.write_settings(&[&dsp_start(ctrl0)]).await?;

        self.max_exposure_lines = u16::try_from(plan.timing.frame_lines).unwrap_or(u16::MAX);
        self.set_exposure(config.exposure).await?;
        Ok(plan)
    }

    /// Switches exposure control (sensor AEC/AGC with a gain ceiling, or manual values).
    pub async fn set_exposure(&mut self, exposure: Exposure) -> Result<(), Error<I::Error>> {
        use reg::sensor::{COM8, COM9};
        match exposure {
            Exposure::Auto { max_gain } => {
                let ceiling = (gain_ceiling_log2(max_gain) - 1) << 5;
                let com9 = self.read_register(Bank::Sensor, COM9).await?;
                let com9 = (com9 & !COM9_CEILING_MASK) | ceiling;
                self.write_settings(&[&[
                    Setting::sensor(COM9, com9),
                    Setting::sensor(COM8, COM8_AUTO),
                ]])
                .await
            }
            Exposure::Manual { lines, gain } => {
                if lines == 0 {
                    return Err(Error::Config(ConfigError::ZeroExposure));
                }
                // AEC/AGC off first, or they overwrite the values after it.
                let manual = self.manual_settings(lines, gain);
                self.write_settings(&[&[Setting::sensor(COM8, COM8_MANUAL)], &manual])
                    .await
            }
        }
    }

    /// Writes exposure (line periods, limited to 1 ..= [`Ov2640::max_exposure_lines`]) and
    /// gain (1x ..= 31x) while in manual mode: four register writes (plus a bank select if
    /// the DSP bank was selected), what a software exposure loop calls per adjustment.
    pub async fn set_manual(&mut self, lines: u16, gain: GainX16) -> Result<(), Error<I::Error>> {
        let manual = self.manual_settings(lines, gain);
        self.write_settings(&[&manual]).await
    }

    /// The register writes of a manual exposure and gain ([`Ov2640::set_manual`]).
    fn manual_settings(&self, lines: u16, gain: GainX16) -> [Setting; 4] {
        use reg::sensor::{AEC, GAIN, REG04, REG45};
        let lines = lines.clamp(1, self.max_exposure_lines.max(1));
        let (high, middle, low) = exposure_fields(lines);
        [
            Setting::sensor(REG45, high),
            Setting::sensor(AEC, middle),
            Setting::sensor(REG04, self.reg04 | low),
            // GAIN has the OV7725's encoding (same formula in both datasheets).
            Setting::sensor(GAIN, gain_register(gain)),
        ]
    }

    /// Reads the exposure (line periods) and gain in force (useful with the sensor's AEC on;
    /// the gain is GAIN's part, which covers the whole range up to the 32x ceiling).
    pub async fn read_exposure(&mut self) -> Result<(u16, GainX16), Error<I::Error>> {
        use reg::sensor::{AEC, GAIN, REG04, REG45};
        let mut values = [0u8; 4];
        for (value, register) in values.iter_mut().zip([REG45, AEC, REG04, GAIN]) {
            *value = self.read_register(Bank::Sensor, register).await?;
        }
        let [reg45, aec, reg04, gain] = values;
        Ok((
            exposure_from_fields(reg45, aec, reg04),
            gain_from_register(gain),
        ))
    }
}

#[cfg(test)]
mod tests;
