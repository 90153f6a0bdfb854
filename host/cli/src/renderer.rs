//! `--renderer raster|warp`, the image model `touchdown simulate`, `touchdown replay
//! --scenario` and `touchdown sitl` render with: one definition, so that the three commands
//! take the same values with the same help.

use touchdown_sim::Renderer;

/// `--renderer`'s values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RendererArg {
    /// Ray casting per pixel averaged over motion-blur sub-frames (the simulator's first model)
    #[default]
    Raster,
    /// The pre-rasterised world through a homography per row, motion blur as each pixel's
    /// footprint swept, its own PSFs and sensor response (much faster)
    Warp,
}

impl RendererArg {
    /// `raster` or `warp` (ASCII case ignored); anything else is one line naming both, for
    /// clap's one-line usage error.
    pub fn parse(text: &str) -> Result<Self, String> {
        if text.eq_ignore_ascii_case("raster") {
            Ok(RendererArg::Raster)
        } else if text.eq_ignore_ascii_case("warp") {
            Ok(RendererArg::Warp)
        } else {
            Err(format!("`{text}` is not a renderer: raster or warp"))
        }
    }

    /// The simulator's renderer.
    pub fn renderer(self) -> Renderer {
        match self {
            RendererArg::Raster => Renderer::Raster,
            RendererArg::Warp => Renderer::Warp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_names_parse_and_anything_else_is_one_line() {
        assert_eq!(RendererArg::parse("raster"), Ok(RendererArg::Raster));
        assert_eq!(RendererArg::parse("Warp"), Ok(RendererArg::Warp));
        assert_eq!(RendererArg::default(), RendererArg::Raster);
        let e = RendererArg::parse("gpu").unwrap_err();
        assert!(e.contains("raster or warp") && !e.contains('\n'), "{e}");
    }
}
