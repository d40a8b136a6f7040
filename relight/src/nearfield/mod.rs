//! Near-field lighting from planar, textured area lights: Sun and
//! Ramamoorthi 2009, *Affine Double- and Triple-Product Wavelet Integrals
//! for Rendering* (ACM TOG 28(2)), §3–5 and Appendix D.
//!
//! A light is an RGB texture `F(u)` over a rectangle in a plane
//! ([`LightTexture`], [`Placement`]). A point at distance `z` in front of
//! the plane and at position `x` in it sees, along the tangent direction
//! `v = (tan θ_x, tan θ_y)`, the radiance `F(z·v + x)` (eq. 29, exact).
//! Over the point's expanded top face ([`PlaneFace`]: `order²` texels of
//! `v ∈ [−side/2, side/2]²`, aligned with the plane, §5.2.1) that is an
//! affine map `u = s·w + o` per axis ([`affine`]), so in the Haar basis the
//! incident lighting is `L_k = Σ_i F_i·D_ik(s, o)` (eq. 30) with the affine
//! coupling coefficients of [`acc`] (eq. 8, 16–18).
//!
//! The 2D basis is the standard (tensor) decomposition, so the 2D coupling
//! is a product of 1D ones (eq. 26) and [`Propagator`] runs the two
//! separable steps of §5.3.1. The light keeps its largest coefficients
//! ([`SourceCoefficients`], source level) and each point computes only the
//! targets a constant light of the same rectangle predicts to be largest
//! ([`Targets::Share`], eq. 32). A transport row over the face
//! ([`transport_coefficients`]) then shades as `B = Σ_k L_k·T_k`.
//!
//! [`NearField`] relights a file's stored near-field rows (chunk NEAR)
//! under [`AreaLight`]s, each row at its stored surface point, by that
//! propagation or by [`exact`] integrals of the light over each face texel
//! ([`NearFieldMethod`]), which truncate nothing and cost less where a
//! light covers part of the face.
//!
//! The couplings are evaluated exactly per point in closed form ([`acc`]);
//! [`AccTable`] tabulates them over quantized `(s, o)`, the memory-based
//! approach of §5.3.2, for a propagation that looks them up instead
//! ([`Propagator::with_table`], [`NearField::set_coupling_table`]).

pub mod acc;
mod acc_table;
pub mod exact;
mod light;
mod propagate;
mod shading_rows;
mod stored;
#[cfg(test)]
mod tests;

pub use acc_table::{AccTable, MAX_WIDTH};
pub use exact::{LightTable, MAX_TABLE_SIDE};
pub use light::{
    haar_2d, LightTexture, Placement, SourceCoefficients, MAX_TEXTURE_SIDE, ROTATION_SAMPLES,
};
pub use propagate::{
    affine, band_starts, transport_coefficients, PlaneFace, Propagator, Receiver, Targets,
    DEFAULT_FACE_SIDE, MIN_SCALE,
};
pub use stored::{AreaLight, NearField, NearFieldMethod, NearFieldTerms};
