use touchdown_core::detect::{Detector, DetectorConfig};
use touchdown_core::family::tables;
use touchdown_core::image::{GrayImage, ImageRegion};
use touchdown_eval::workspace::HostWorkspace;
#[test]
fn scratch() {
    let path = std::env::var("PGM").unwrap();
    let d = std::fs::read(&path).unwrap();
    let px = &d[d.len() - 640 * 480..];
    let img = GrayImage::new(px, 640, 480).unwrap();
    let mut ws = HostWorkspace::new();
    let mut det = Detector::new(DetectorConfig::default());
    for (x, y, s) in [
        (260usize, 130usize, 140usize),
        (280, 150, 100),
        (300, 160, 70),
        (0, 0, 0),
    ] {
        let mut b = ws.buffers(640, 480);
        let r = if s == 0 {
            det.detect(&img, tables::DEFAULT, &mut b).map(|d| d.len())
        } else {
            det.detect_region(
                &img,
                &ImageRegion {
                    x,
                    y,
                    width: s,
                    height: s,
                },
                tables::DEFAULT,
                &mut b,
            )
            .map(|d| d.len())
        };
        println!("{x} {y} {s}: {:?} {:?}", r, det.stats());
        for d in det.detections() {
            println!("   id {} corners {:?}", d.id, d.corners);
        }
    }
}
