//! The `config_toml` target: the `camera.toml` and `pad.toml` parsers of `touchdown-formats`
//! on arbitrary text.

use touchdown_formats::camera::parse_camera;
use touchdown_formats::pad::parse_pad;

/// `camera.toml` and `pad.toml` parsers on arbitrary text: an accepted camera validates in
/// the core (so pose will not reject it later); an accepted pad builds its core layout.
pub fn config_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match parse_camera(text) {
        Ok(camera) => assert_eq!(camera.validate(), Ok(()), "accepted camera {camera:?}"),
        Err(e) => assert!(!e.reason.is_empty()),
    }
    match parse_pad(text) {
        Ok(pad) => {
            let layout = pad.layout().expect("an accepted pad builds its layout");
            assert!(!layout.markers().is_empty());
        }
        Err(e) => assert!(!e.reason.is_empty()),
    }
}
