//! When to save: [`SaveDebounce`] turns a burst of parameter writes into one save.
//!
//! Separate from the log: it only compares parameter sets over time, and the firmware runs it
//! in its link task while the store lives in the flash task.

use crate::params::ParamSet;

/// A changed parameter set is saved once it has not changed for this long, µs.
pub const SAVE_DEBOUNCE_US: u64 = 2_000_000;

/// Decides when to save: a parameter set different from the saved one, unchanged for
/// [`SAVE_DEBOUNCE_US`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SaveDebounce {
    saved: ParamSet,
    seen: ParamSet,
    since_us: u64,
}

impl SaveDebounce {
    /// Starts from the set that is in flash (or the defaults).
    pub fn new(saved: ParamSet) -> Self {
        SaveDebounce {
            saved,
            seen: saved,
            since_us: 0,
        }
    }

    /// Looks at the current set at `now_us`; returns it when it is due for saving.
    pub fn poll(&mut self, current: &ParamSet, now_us: u64) -> Option<ParamSet> {
        if *current != self.seen {
            self.seen = *current;
            self.since_us = now_us;
        }
        let due =
            self.seen != self.saved && now_us.saturating_sub(self.since_us) >= SAVE_DEBOUNCE_US;
        due.then_some(self.seen)
    }

    /// Records a successful save of `params`.
    pub fn saved(&mut self, params: &ParamSet) {
        self.saved = *params;
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_fixtures::with_profile;
    use super::*;
    use crate::params::ParamId;

    #[test]
    fn debounce_waits_for_a_stable_change() {
        let mut d = SaveDebounce::new(ParamSet::default());
        assert_eq!(d.poll(&ParamSet::default(), 10_000_000), None);
        let a = with_profile(1.0);
        assert_eq!(d.poll(&a, 20_000_000), None);
        assert_eq!(d.poll(&a, 21_000_000), None);
        // Another change restarts the wait.
        let mut b = a;
        b.set(ParamId::RateHz, 10.0).unwrap();
        assert_eq!(d.poll(&b, 21_500_000), None);
        assert_eq!(d.poll(&b, 23_000_000), None);
        assert_eq!(d.poll(&b, 23_500_000), Some(b));
        d.saved(&b);
        assert_eq!(d.poll(&b, 30_000_000), None);
        // Changed back to what is saved: nothing to do.
        d.poll(&a, 31_000_000);
        assert_eq!(d.poll(&b, 31_100_000), None);
        assert_eq!(d.poll(&b, 40_000_000), None);
    }
}
