//! The MAVLink signing secret the board keeps beside its parameters: the 32-byte key set by
//! SETUP_SIGNING and the timestamp it came with.
//!
//! It lives in [`ParamSet`](super::ParamSet) so that it is saved and restored by the same
//! power-safe log as the parameters, in the same slot (a key and the parameters it protects
//! can never come from two different saves), but it is not a parameter: it has no index, no
//! PARAM_VALUE ever carries it, and it is written only by a SETUP_SIGNING the companion
//! accepted. In the export blob it is [`RECORDS`] records whose names start with `#`, which
//! no parameter name does: a firmware that does not know them counts them as unknown and
//! keeps going.

/// Bytes of a signing key.
pub const KEY_LEN: usize = 32;
/// Export records the secret takes: the key in 4-byte pieces, then the timestamp's low and
/// high halves.
pub(super) const RECORDS: usize = KEY_LEN / 4 + 2;
/// The names of those records, in order.
const NAMES: [&str; RECORDS] = [
    "#SIGNKEY0",
    "#SIGNKEY1",
    "#SIGNKEY2",
    "#SIGNKEY3",
    "#SIGNKEY4",
    "#SIGNKEY5",
    "#SIGNKEY6",
    "#SIGNKEY7",
    "#SIGNTS0",
    "#SIGNTS1",
];

/// A signing key and its initial timestamp (MAVLink's 10 µs units since 2015-01-01). The
/// all-zero key is "no key": signing off, as SETUP_SIGNING with a zero key means.
#[derive(Clone, Copy, PartialEq, Eq, Default)]
pub struct SigningSecret {
    key: [u8; KEY_LEN],
    timestamp: u64,
}

impl core::fmt::Debug for SigningSecret {
    // Never the key itself: a debug print goes to logs and terminals.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SigningSecret")
            .field("key", &if self.is_set() { "set" } else { "none" })
            .field("timestamp", &self.timestamp)
            .finish()
    }
}

impl SigningSecret {
    /// No key: signing off.
    pub const NONE: SigningSecret = SigningSecret {
        key: [0; KEY_LEN],
        timestamp: 0,
    };

    /// `key` with its initial `timestamp`; an all-zero key is [`SigningSecret::NONE`].
    pub fn new(key: [u8; KEY_LEN], timestamp: u64) -> Self {
        if key == [0; KEY_LEN] {
            Self::NONE
        } else {
            SigningSecret { key, timestamp }
        }
    }

    /// Whether a key is set.
    pub fn is_set(&self) -> bool {
        self.key != [0; KEY_LEN]
    }

    /// The key, when one is set.
    pub fn key(&self) -> Option<&[u8; KEY_LEN]> {
        self.is_set().then_some(&self.key)
    }

    /// The timestamp saved with the key: the one it was set with, or past the last signed
    /// write the board applied ([`SigningSecret::after_write`]). No signed frame older counts.
    pub fn timestamp(&self) -> u64 {
        self.timestamp
    }

    /// The secret once a write signed at `timestamp` has been applied: its saved timestamp past
    /// that write's, so that the write cannot be played again after a reboot (when the
    /// board's record of its senders is gone).
    pub fn after_write(&self, timestamp: u64) -> SigningSecret {
        SigningSecret {
            key: self.key,
            timestamp: self.timestamp.max(timestamp.saturating_add(1)),
        }
    }

    /// The records: name and 4 bytes each, in [`NAMES`] order.
    pub(super) fn records(&self) -> [(&'static str, [u8; 4]); RECORDS] {
        let ts = self.timestamp.to_le_bytes();
        let mut out = NAMES.map(|n| (n, [0u8; 4]));
        for ((_, dst), src) in out
            .iter_mut()
            .zip(self.key.chunks_exact(4).chain(ts.chunks_exact(4)))
        {
            dst.copy_from_slice(src);
        }
        out
    }
}

/// Assembles a [`SigningSecret`] from the records of an import blob.
#[derive(Default)]
pub(super) struct SecretRecords {
    words: [[u8; 4]; RECORDS],
    seen: u16,
}

impl SecretRecords {
    /// Takes the record `name` if it is one of the secret's; `false` for any other name.
    pub(super) fn take(&mut self, name: &str, value: [u8; 4]) -> bool {
        let Some(i) = NAMES.iter().position(|n| *n == name) else {
            return false;
        };
        if let Some(w) = self.words.get_mut(i) {
            *w = value;
            self.seen |= 1 << i;
        }
        true
    }

    /// The secret, when every record was there (a blob without them, from a firmware before
    /// signing, gives `None`: the secret stays as it was).
    pub(super) fn finish(&self) -> Option<SigningSecret> {
        if self.seen != (1 << RECORDS) - 1 {
            return None;
        }
        let mut key = [0u8; KEY_LEN];
        for (dst, src) in key.chunks_exact_mut(4).zip(self.words.iter()) {
            dst.copy_from_slice(src);
        }
        let mut ts = [0u8; 8];
        for (dst, src) in ts
            .chunks_exact_mut(4)
            .zip(self.words.iter().skip(KEY_LEN / 4))
        {
            dst.copy_from_slice(src);
        }
        Some(SigningSecret::new(key, u64::from_le_bytes(ts)))
    }
}
