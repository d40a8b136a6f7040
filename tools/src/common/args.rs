//! Argument groups shared by several commands, flattened into their
//! argument structs: the image outputs and the number of terms per frame.

use anyhow::{Context, Result};
use clap::Args;
use ltm_codec::AtomicFile;
use ltm_relight::{Image, Relight, TermBasis, Weighting};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use super::Exposure;

/// The image outputs of `ltm relight`, `ltm render` and `ltm reference`:
/// a linear EXR and an optional tone-mapped PNG.
#[derive(Args)]
pub struct ImageOutput {
    /// Output image: 32-bit float linear RGB OpenEXR (numbered OUT-000.exr,
    /// OUT-001.exr, ... where a command writes several views).
    /// A name ending in another image format's extension (.png, .jpg,
    /// .hdr, ...) is refused: the PNG comes from --png.
    #[arg(short, long, value_name = "OUT.exr", value_parser = exr_name)]
    pub output: PathBuf,
    /// Also write a tone-mapped 8-bit sRGB PNG (numbered like the EXR where
    /// a command writes several views).
    /// A name ending in another image format's extension is refused.
    #[arg(long, value_name = "OUT.png", value_parser = png_name)]
    pub png: Option<PathBuf>,
    /// Exposure of the PNG: `auto` maps the 99th-percentile luminance of the
    /// image to 0.8 (for an orbit of views, of the first view, so that every
    /// view has the same exposure), or a number of stops EV in -64..=64
    /// (values are multiplied by 2^EV before clamping to [0, 1]). The EV
    /// used is printed.
    #[arg(
        long,
        value_name = "auto|EV",
        default_value = "auto",
        allow_hyphen_values = true
    )]
    pub exposure: Exposure,
}

/// Extensions of image formats, lower case.
const IMAGE_EXTENSIONS: [&str; 10] = [
    "exr", "png", "jpg", "jpeg", "hdr", "tif", "tiff", "bmp", "ppm", "webp",
];

/// `name` as a path, refused when its extension names an image format
/// other than `format` (a file written in one format under another's name
/// misleads every program that opens it).
fn image_name(name: &str, format: &str, flag: &str, hint: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(name);
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase());
    match ext {
        Some(e) if e != format && IMAGE_EXTENSIONS.contains(&e.as_str()) => Err(format!(
            "'{name}' ends in .{e}, but {flag} writes {} ({hint})",
            format.to_uppercase()
        )),
        _ => Ok(path),
    }
}

fn exr_name(name: &str) -> Result<PathBuf, String> {
    image_name(name, "exr", "-o", "name it .exr; --png OUT.png adds a PNG")
}

fn png_name(name: &str) -> Result<PathBuf, String> {
    image_name(name, "png", "--png", "name it .png; -o writes the EXR")
}

impl ImageOutput {
    /// The outputs as (role, path) pairs for [`super::claim_files`].
    pub fn roles(&self) -> Vec<(&'static str, &Path)> {
        let mut outputs = vec![("-o", self.output.as_path())];
        if let Some(png) = &self.png {
            outputs.push(("--png", png.as_path()));
        }
        outputs
    }

    /// The PNG's exposure for `image` (see [`Exposure::resolve`]).
    pub fn ev(&self, image: &Image) -> f32 {
        self.exposure.resolve(image)
    }

    /// Writes `image` as the EXR and, when asked for, the PNG: both
    /// appear, or neither. Prints the PNG's exposure.
    pub fn write(&self, image: &Image) -> Result<()> {
        let ev = self.ev(image);
        let staged = self.stage(image, &self.output, self.png.as_deref(), ev)?;
        commit_all(staged)?;
        self.print_exposure(ev);
        Ok(())
    }

    /// Prints the exposure `ev` of the PNG, when one is written.
    pub fn print_exposure(&self, ev: f32) {
        if let Some(png) = &self.png {
            eprintln!("{}: {}", png.display(), self.exposure.describe(ev));
        }
    }

    /// Writes `image` as the EXR `exr` and, when given, the PNG `png` at
    /// exposure `ev`, uncommitted ([`Image::stage_exr`]): they appear when
    /// passed to [`commit_all`].
    pub fn stage(
        &self,
        image: &Image,
        exr: &Path,
        png: Option<&Path>,
        ev: f32,
    ) -> Result<Vec<AtomicFile>> {
        let mut files = vec![image
            .stage_exr(exr)
            .with_context(|| format!("writing {}", exr.display()))?];
        if let Some(png) = png {
            files.push(
                image
                    .stage_png(png, ev)
                    .with_context(|| format!("writing {}", png.display()))?,
            );
        }
        Ok(files)
    }
}

/// Commits files staged together, after all of them were written: a run
/// that fails while writing leaves none of them.
pub fn commit_all(files: Vec<AtomicFile>) -> Result<()> {
    for f in files {
        let path = f.path().to_path_buf();
        f.commit()
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// How many terms a frame uses: a positive count, or `all`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Terms(pub usize);

impl Terms {
    /// `all`.
    pub const ALL: Terms = Terms(usize::MAX);
}

impl FromStr for Terms {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Terms, String> {
        if s == "all" {
            return Ok(Terms::ALL);
        }
        match s.parse::<usize>() {
            Ok(0) | Err(_) => Err(format!("terms '{s}' must be a positive integer or 'all'")),
            Ok(n) => Ok(Terms(n)),
        }
    }
}

/// The terms of a frame: `--terms` and `--weighting`.
#[derive(Args)]
pub struct TermsArgs {
    /// Wavelet lights per frame (non-linear approximation), or `all`.
    /// Values above the number of lights use them all. For a pca file: the
    /// first N eigen-transports (at most the rank stored). [default: 200
    /// wavelet lights; every eigen-transport of a pca file]
    #[arg(long)]
    pub terms: Option<Terms>,
    /// Priority of wavelet lights: unweighted |c|, transport |c|·‖T_j‖, or
    /// area |c|·support area (Ng et al. 2003).
    #[arg(long, default_value = "unweighted")]
    pub weighting: Weighting,
}

/// The terms a frame used, named as docs/GLOSSARY.md names them:
/// `200 wavelet lights` or `48 principal components` (a pca file).
pub fn describe_terms(relighter: &dyn Relight, used: usize) -> String {
    let (one, many) = match relighter.term_basis() {
        TermBasis::Wavelet => ("wavelet light", "wavelet lights"),
        TermBasis::Linear => ("principal component", "principal components"),
    };
    format!("{used} {}", if used == 1 { one } else { many })
}

/// Wavelet lights per frame when `--terms` is not given.
pub const DEFAULT_WAVELET_TERMS: usize = 200;

impl TermsArgs {
    /// The number of terms to request from `relighter`. A linear basis (a
    /// pca file) refuses more terms than it stores; `all` and the default
    /// mean all of them there.
    pub fn resolve(&self, relighter: &dyn Relight) -> usize {
        let linear = relighter.term_basis() == TermBasis::Linear;
        match self.terms {
            Some(Terms::ALL) => relighter.max_terms(),
            Some(Terms(t)) => t,
            None if linear => relighter.max_terms(),
            None => DEFAULT_WAVELET_TERMS,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terms_are_positive_or_all() {
        assert_eq!("all".parse::<Terms>(), Ok(Terms::ALL));
        assert_eq!("7".parse::<Terms>(), Ok(Terms(7)));
        for bad in ["0", "-1", "x", "", "1.5"] {
            let e = bad.parse::<Terms>().unwrap_err();
            assert!(e.contains(&format!("'{bad}'")), "{e}");
        }
    }
}
