//! `--signing-key`: the MAVLink 2 signing key a host tool holds (docs/signing.md).
//!
//! The key is 32 bytes. Users rarely type 64 hex digits, and ground stations derive keys from
//! a passphrase (MAVProxy's `signing setup` hashes it with SHA-256); both are taken: exactly 64
//! hex digits are the key itself, anything else is a passphrase.

use touchdown_core::params::KEY_LEN;
use touchdown_core::sha256::Sha256;

/// The key `text` gives (see the module documentation).
pub fn parse(text: &str) -> Result<[u8; KEY_LEN], String> {
    if text.is_empty() {
        return Err("empty: give 64 hex digits or a passphrase".into());
    }
    let hex = text.len() == 2 * KEY_LEN && text.bytes().all(|b| b.is_ascii_hexdigit());
    let key = if hex {
        let mut key = [0u8; KEY_LEN];
        for (k, pair) in key.iter_mut().zip(text.as_bytes().chunks_exact(2)) {
            let digits = std::str::from_utf8(pair).map_err(|e| e.to_string())?;
            *k = u8::from_str_radix(digits, 16).map_err(|e| e.to_string())?;
        }
        key
    } else {
        let mut h = Sha256::new();
        h.update(text.as_bytes());
        h.finish()
    };
    if key == [0; KEY_LEN] {
        return Err("all zeros, which means \"no key\" in MAVLink".into());
    }
    Ok(key)
}

/// Now as a signing timestamp: 10 µs units since 2015-01-01 UTC (0 if the clock is before it).
pub fn timestamp_now() -> u64 {
    const EPOCH_2015_S: u64 = 1_420_070_400;
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| {
            d.as_micros()
                .saturating_sub(u128::from(EPOCH_2015_S) * 1_000_000)
                / 10
        })
        .map_or(0, |t| u64::try_from(t).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_is_the_key_and_anything_else_a_passphrase() {
        let hex = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";
        let key = parse(hex).unwrap();
        assert_eq!(key[0], 0);
        assert_eq!(key[31], 0x1f);
        // SHA-256 of "abc" (FIPS 180-4), as MAVProxy's `signing setup abc` would use.
        let key = parse("abc").unwrap();
        assert_eq!(&key[..4], &[0xba, 0x78, 0x16, 0xbf]);
        assert!(parse("").is_err());
        assert!(parse(&"0".repeat(64)).is_err());
        // 63 hex digits: a passphrase.
        assert_ne!(parse(&hex[1..]).unwrap()[..], parse(hex).unwrap()[..]);
        assert!(timestamp_now() > 11 * 365 * 24 * 3600 * 100_000);
    }
}
