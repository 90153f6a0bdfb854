//! The `recording` target: the `frames.csv` parser and the PGM reader of `touchdown-formats`
//! on arbitrary bytes.

use touchdown_formats::pgm::parse_pgm;
use touchdown_formats::recording::parse_frames_csv;

/// The recording readers: `frames.csv` (even byte 0) or an 8-bit binary PGM (odd byte 0,
/// with an expected size from byte 0's upper bits when bit 1 is set). Accepted rows count up
/// from 0 with increasing times and finite truth; an accepted PGM holds exactly
/// width x height pixels of the expected size.
pub fn recording(data: &[u8]) {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    if selector & 1 == 0 {
        let Ok(text) = std::str::from_utf8(rest) else {
            return;
        };
        if let Ok((has_truth, entries)) = parse_frames_csv(text) {
            for (k, e) in entries.iter().enumerate() {
                assert_eq!(e.index, k);
                if let Some(previous) = k.checked_sub(1).and_then(|p| entries.get(p)) {
                    assert!(e.t_us > previous.t_us);
                }
                if let Some(truth) = &e.truth {
                    assert!(has_truth);
                    assert!(truth
                        .position
                        .iter()
                        .chain(truth.orientation.iter())
                        .all(|v| v.is_finite()));
                }
            }
        }
    } else {
        let expected = (selector & 2 != 0).then(|| {
            (
                usize::from((selector >> 2) & 7) + 1,
                usize::from(selector >> 5) + 1,
            )
        });
        if let Ok(frame) = parse_pgm(rest, expected) {
            assert_eq!(frame.pixels.len(), frame.width * frame.height);
            if let Some(size) = expected {
                assert_eq!((frame.width, frame.height), size);
            }
        }
    }
}
