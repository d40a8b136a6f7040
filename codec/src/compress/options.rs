//! The user's choices of how to code: the [`Mode`] (how columns are
//! transformed) and the [`Entropy`] coder of the payloads.

/// How columns were transformed (serialized by its [`Mode::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Mode {
    /// Rows only (Ng et al. 2003): every column at depth 0.
    #[serde(rename = "2d")]
    TwoD,
    /// Every column to full depth.
    #[serde(rename = "4d")]
    FourD,
    /// Each column to the depth that codes it best (Cheslack-Postava et al. 2007).
    #[serde(rename = "adaptive")]
    Adaptive,
    /// Mean-centred principal components of the rows (Eigentransport):
    /// chunks `PCAM`, `PCAB`, `PCAC` instead of `COLS` and `DATA`
    /// (format version 2).
    #[serde(rename = "pca")]
    Pca,
}

impl Mode {
    /// The mode's name on the command line and in reports: `2d`, `4d` or
    /// `adaptive`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::TwoD => "2d",
            Mode::FourD => "4d",
            Mode::Adaptive => "adaptive",
            Mode::Pca => "pca",
        }
    }
    pub(crate) fn code(self) -> u8 {
        match self {
            Mode::TwoD => 0,
            Mode::FourD => 1,
            Mode::Adaptive => 2,
            Mode::Pca => 3,
        }
    }
    /// True for the wavelet modes (columns in `COLS`/`DATA`).
    pub fn is_wavelet(self) -> bool {
        self != Mode::Pca
    }
    pub(crate) fn from_code(c: u8) -> Option<Mode> {
        [Mode::TwoD, Mode::FourD, Mode::Adaptive, Mode::Pca]
            .into_iter()
            .find(|m| m.code() == c)
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Mode, String> {
        match s {
            "2d" => Ok(Mode::TwoD),
            "4d" => Ok(Mode::FourD),
            "adaptive" => Ok(Mode::Adaptive),
            "pca" => Ok(Mode::Pca),
            _ => Err(format!(
                "unknown mode '{s}' (expected 2d, 4d, adaptive or pca)"
            )),
        }
    }
}

/// How the encoder stores column payloads.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Entropy {
    /// Range-coded with context modelling (encoding 4) where that is no
    /// larger than the plain payload: the smallest files.
    #[default]
    Range,
    /// zstd frames (encoding 2), as format versions 1 and 2 wrote: larger
    /// files that decode, and so open, several times faster.
    Zstd,
}

impl std::str::FromStr for Entropy {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Entropy, String> {
        match s {
            "range" => Ok(Entropy::Range),
            "zstd" => Ok(Entropy::Zstd),
            _ => Err(format!(
                "unknown entropy coder '{s}' (expected range or zstd)"
            )),
        }
    }
}
