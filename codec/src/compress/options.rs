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

/// How the coder quantizes the kept coefficients of a target-error run.
/// The decoder does not need to know: both store per scale group a scale
/// `s`, and a value decodes as `q·s/Q` (docs/FORMAT.md).
#[non_exhaustive]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Quantizer {
    /// One step for the whole matrix, tied to the threshold τ
    /// ([`UNIFORM_STEP_PER_THRESHOLD`]·τ per channel, in the band-weighted
    /// domain), with values rounded to the nearest step: the entropy-coded
    /// uniform quantizer, which spends the error where it buys the most
    /// bytes. A scale group whose largest value exceeds `Q` steps gets the
    /// coarser step `peak/Q`. Term-count runs (`--keep`), which have no τ,
    /// quantize with [`Quantizer::Peak`].
    #[default]
    #[serde(rename = "uniform")]
    Uniform,
    /// Each scale group's step is its largest kept value over `Q =
    /// 2^(bits−1) − 1`, with a dither (every file before the uniform
    /// quantizer was written so): many bits for every kept value, most of
    /// them noise.
    #[serde(rename = "peak")]
    Peak,
}

/// The uniform quantizer's step over the threshold (per channel): values
/// below τ are dropped, values from τ to 2.25·τ round to one step. So the
/// zero bin is wider than the others (a deadzone of 1.33 steps). 1.5 gave
/// smaller files than 2 on a grey and two RGB matrices at 0.3–3 %, and
/// than 2.5 and 3 on the grey one but for a tie at 1 %
/// (docs/results/codec.md).
pub const UNIFORM_STEP_PER_THRESHOLD: f64 = 1.5;

impl Quantizer {
    /// The quantizer of options serialized before the uniform one existed.
    pub(crate) fn before_uniform() -> Quantizer {
        Quantizer::Peak
    }

    /// The name on the command line: `uniform` or `peak`.
    pub fn name(self) -> &'static str {
        match self {
            Quantizer::Uniform => "uniform",
            Quantizer::Peak => "peak",
        }
    }

    /// The bits a run takes when none are given: 16 for the uniform
    /// quantizer, whose bits only bound how many steps a value may take
    /// (fewer would coarsen the steps of the bands with the largest values),
    /// [`DEFAULT_BITS`](super::DEFAULT_BITS) for the peak quantizer.
    pub fn default_bits(self) -> u32 {
        match self {
            Quantizer::Uniform => 16,
            Quantizer::Peak => super::DEFAULT_BITS,
        }
    }

    /// The weighted step per channel of the uniform quantizer at the
    /// threshold `tau_sq` (a squared magnitude summed over `channels`);
    /// `None` for the peak quantizer or without a threshold.
    pub fn step(self, tau_sq: f64, channels: usize) -> Option<f64> {
        match self {
            Quantizer::Uniform if tau_sq > 0.0 => {
                Some(UNIFORM_STEP_PER_THRESHOLD * (tau_sq / channels.max(1) as f64).sqrt())
            }
            _ => None,
        }
    }
}

impl std::str::FromStr for Quantizer {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Quantizer, String> {
        match s {
            "uniform" => Ok(Quantizer::Uniform),
            "peak" => Ok(Quantizer::Peak),
            _ => Err(format!(
                "unknown quantizer '{s}' (expected uniform or peak)"
            )),
        }
    }
}
