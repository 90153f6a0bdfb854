//! The `frame_stream` target: the board's frame stream as a viewer reads it
//! (`touchdown_formats::frame_stream::StreamReader`) and the viewer's requests as the board
//! reads them (`touchdown_core::frame_stream::RequestParser`), on arbitrary bytes.

use touchdown_core::frame_stream::{RequestParser, MAX_MARKERS, MAX_PIXELS};
use touchdown_formats::frame_stream::StreamReader;

/// Byte 0 sets the chunk size (1 to 256) the rest is fed in. Every record the reader returns
/// has as many pixels as its size says (at most a VGA frame), a scale of 1 or 2, at most
/// [`MAX_MARKERS`] markers; the reader's counts add up (records, skipped bytes, bad
/// checksums never exceed the input); every request the parser returns asks for every frame
/// or fewer (at least 1) at a scale of 1 or 2.
pub fn frame_stream(data: &[u8]) {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(selector) + 1;
    let mut reader = StreamReader::new();
    let mut requests = RequestParser::new();
    let mut records = 0u64;
    for piece in rest.chunks(chunk) {
        reader.push(piece);
        while let Some(frame) = reader.next_frame() {
            records += 1;
            assert_eq!(frame.pixels.len(), frame.width * frame.height);
            assert!(frame.pixels.len() <= MAX_PIXELS && !frame.pixels.is_empty());
            assert!(matches!(frame.scale, 1 | 2));
            assert!(frame.markers.len() <= MAX_MARKERS);
            let sent = frame.sent_camera();
            assert_eq!(
                (sent.width as usize, sent.height as usize),
                (frame.width, frame.height)
            );
        }
        if let Some(request) = requests.push(piece) {
            assert!(request.every >= 1);
            assert!(matches!(request.scale, 1 | 2));
        }
    }
    let stats = reader.stats();
    assert_eq!(stats.records, records);
    assert!(stats.skipped_bytes <= rest.len() as u64);
    assert!(stats.bad_checksums <= rest.len() as u64);
}
