//! The GAIN register's encoding: an analog gain as doublings and sixteenths.
//!
//! Separate from the driver because the OV2640's GAIN register has the same encoding (same
//! formula in both datasheets) and its driver uses these two functions too.

use crate::GainX16;

/// Encodes a gain for the GAIN register (clamped to 1x ... 31x, the register's range).
pub fn gain_register(gain: GainX16) -> u8 {
    let g = gain.0.clamp(16, 16 * 32);
    // Number of doublings: g in [16 << k, 32 << k).
    let mut k = 0u16;
    while k < 4 && g >= (32u16 << k) {
        k += 1;
    }
    let fine = ((g >> k).saturating_sub(16)).min(15) as u8;
    let doublings = ((1u16 << k) - 1) as u8;
    (doublings << 4) | fine
}

/// Decodes the GAIN register.
pub fn gain_from_register(value: u8) -> GainX16 {
    let doublings = (value >> 4).count_ones();
    GainX16((16 + u16::from(value & 0x0F)) << doublings)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gain_encoding() {
        assert_eq!(gain_register(GainX16::ONE), 0x00);
        assert_eq!(gain_register(GainX16(32)), 0x10);
        assert_eq!(gain_register(GainX16(40)), 0x14);
        assert_eq!(gain_register(GainX16(128)), 0x70);
        assert_eq!(gain_register(GainX16(0)), 0x00); // below 1x: clamped
        assert_eq!(gain_register(GainX16(u16::MAX)), 0xFF); // 31x, the largest
        for g in 16..=496u16 {
            let r = gain_register(GainX16(g));
            let back = gain_from_register(r).0;
            // Rounded down by less than one step of the fine field at that doubling.
            let step = 1u16 << (r >> 4).count_ones();
            assert!(back <= g && g - back < step, "{g} {back}");
        }
    }
}
