//! Recall and wrong ids of touchdown's offline detector on the hard still set
//! (`touchdown_eval::stills`), per class and image model.
//!
//! ```text
//! cargo run --release -p touchdown-host-tests --example hard_stills -- \
//!     [--count N] [--seed S] [--class NAME] [--write DIR] [--verbose]
//! ```
//!
//! `--count` stills per class and renderer (default 50), drawn from `--seed` (default 1; the
//! long test uses seed 0, so other seeds are stills it never saw). `--write DIR` also saves
//! every still as `DIR/<renderer>-<class>-<index>.png` with a `truth.csv` (family, id, corners
//! in the contract's order and pixel convention), for other detectors and for looking.
//! `--class` takes one class only (shadow-corner, oblique, wide-lens, small); `--verbose` lists
//! the stills missed.

use std::fmt::Write as _;
use std::path::PathBuf;

use touchdown_eval::stills::{score_class_showing, Still, StillClass};
use touchdown_formats::image_io::save_png;
use touchdown_sim::Renderer;

struct Args {
    count: u64,
    seed: u64,
    write: Option<PathBuf>,
    verbose: bool,
    classes: Vec<StillClass>,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        count: 50,
        seed: 1,
        write: None,
        verbose: false,
        classes: StillClass::ALL.to_vec(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut number = |name: &str| -> Result<u64, String> {
            let value = it.next().ok_or(format!("{name} needs a number"))?;
            value.parse().map_err(|_| format!("bad {name} {value}"))
        };
        match arg.as_str() {
            "--count" => args.count = number("--count")?,
            "--seed" => args.seed = number("--seed")?,
            "--write" => {
                args.write = Some(PathBuf::from(it.next().ok_or("--write needs a directory")?))
            }
            "--verbose" => args.verbose = true,
            "--class" => {
                let value = it.next().ok_or("--class needs a name")?;
                let class = StillClass::ALL
                    .into_iter()
                    .find(|c| c.name() == value)
                    .ok_or(format!("no class {value}"))?;
                args.classes = vec![class];
            }
            other => {
                return Err(format!(
                    "unknown argument {other} (--count N, --seed S, --class NAME, --write DIR, --verbose)"
                ))
            }
        }
    }
    Ok(args)
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("hard_stills: {e}");
            std::process::exit(2);
        }
    };
    let mut truth = String::from("file,family,id,x0,y0,x1,y1,x2,y2,x3,y3\n");
    if let Some(dir) = &args.write {
        if let Err(e) = std::fs::create_dir_all(dir) {
            eprintln!("hard_stills: {}: {e}", dir.display());
            std::process::exit(1);
        }
    }
    let mut failed = None;
    for renderer in [Renderer::Raster, Renderer::Warp] {
        for &class in &args.classes {
            let save = |index: u64, still: &Still| {
                let Some(dir) = &args.write else {
                    return;
                };
                let name = format!("{}-{}-{index:03}.png", renderer.name(), class.name());
                if let Err(e) = save_png(&dir.join(&name), &still.image) {
                    failed.get_or_insert(format!("{name}: {e}"));
                }
                let _ = write!(truth, "{name},{},{}", still.family, still.id);
                for c in still.corners {
                    let _ = write!(truth, ",{:.3},{:.3}", c[0], c[1]);
                }
                truth.push('\n');
            };
            let score = score_class_showing(class, args.count, renderer, args.seed, save);
            println!("{} {}: {}", renderer.name(), class.name(), score.summary());
            for w in &score.wrong {
                println!("    wrong: {w}");
            }
            if args.verbose {
                for m in &score.missed {
                    println!("    missed: {m}");
                }
            }
        }
    }
    if let Some(dir) = &args.write {
        let written = std::fs::write(dir.join("truth.csv"), truth);
        if let Some(e) = failed.or(written.err().map(|e| format!("truth.csv: {e}"))) {
            eprintln!("hard_stills: {e}");
            std::process::exit(1);
        }
    }
}
