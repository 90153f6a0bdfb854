//! Checksums shared by modules that must not depend on each other.
//!
//! The MAVLink parser ([`crate::companion`]) and the parameter export
//! ([`crate::params`]) both use MAVLink's X.25 checksum; it lives here so that neither has to
//! import the other (the companion depends on the parameter table, never the reverse).

/// Accumulates `bytes` into an X.25 (CRC-16/MCRF4XX) checksum, MAVLink's: start from
/// `0xFFFF`, no final XOR.
pub fn crc16_x25(mut crc: u16, bytes: &[u8]) -> u16 {
    for &b in bytes {
        let mut tmp = b ^ (crc & 0xFF) as u8;
        tmp ^= tmp << 4;
        let t = u16::from(tmp);
        crc = (crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4);
    }
    crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn x25_check_value() {
        // The catalogue's check value of CRC-16/MCRF4XX.
        assert_eq!(crc16_x25(0xFFFF, b"123456789"), 0x6F91);
    }
}
